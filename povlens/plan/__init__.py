"""Planning: from a scene and a lens to a render folder's plan.

Modules, lowest first: ``options`` (what a conversion is asked for), ``schema`` (the
plan's typed records, :func:`~povlens.plan.schema.read_plan` /
:func:`~povlens.plan.schema.write_plan`), ``depth_probe`` (scene distances by a POV-Ray
light that fades with distance), ``camera_setup`` (the camera, film and focus from the
options and the scene's camera), ``plan_start`` and ``plan_finish`` (the plan of a given
method, in two steps), ``batches`` (lens samples dealt to batches), ``autofocus``
(the focus distance from the scene), ``decision`` (``--method auto``'s pure
choice), ``adaptive`` (row bands of adaptive mesh sampling), ``auto`` (probe, measure,
decide), ``render_folder`` (the render folder's file names), ``folder_writer``
(plan.json, wrappers, Makefile), ``speculative`` (what
``povlens render`` starts before the decision), ``convert`` (the entry point).
"""
