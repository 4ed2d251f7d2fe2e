"""povlens: real camera lenses for POV-Ray.

Pipeline (one module per concept):
prescription -> tracer (and reference_tracer) -> paraxial / focus -> pupil tables
-> focal-plane model -> POV-Ray emission -> rendering and compositing -> reports.
Coordinate frames are defined once, in :mod:`povlens.frames`.
"""

__version__ = "0.1.0"
