"""povlens: real camera lenses for POV-Ray.

The package is the pipeline, one subpackage per stage, each importing only the ones
before it::

    lens/      prescriptions, frames, paraxial optics, the real-ray tracers, focus, film
    pupil/     exit-pupil tables, lens sampling, lens rays per pixel
    thinlens/  the equivalent focal-plane (thin-lens) model and its measured error
    pov/       reading scene cameras, emitting wrappers and ray meshes, running POV-Ray
    plan/      the plan schema, fixed and automatic conversion, the depth probe
    rendering/ rendering lens samples, compositing
    report/    image comparison and the HTML report
    bench/     time-against-error benchmarks
    cli/       the command line, a thin layer over this API

The public API (``povlens.__all__``) is loaded on first use, so ``import povlens``
stays cheap for the command line.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

# public name -> module that defines it
_API = {
    "read_lens": "povlens.api",
    "focus": "povlens.api",
    "convert": "povlens.api",
    "render": "povlens.api",
    "composite": "povlens.api",
    "compare": "povlens.api",
    "RenderResult": "povlens.api",
    "render_frames": "povlens.api",
    "FramesResult": "povlens.api",
    "convert_frames": "povlens.api",
    "renderer_for": "povlens.api",
    "RenderFolder": "povlens.api",
    "import_lens": "povlens.api",
    "bundled_lenses": "povlens.lens.bundled",
    "build_pupil_table": "povlens.pupil.build",
    "PupilTable": "povlens.pupil.table",
    "LensPrescription": "povlens.lens.prescription",
    "FocusResult": "povlens.lens.focus",
    "ConvertOptions": "povlens.plan.options",
    "Plan": "povlens.plan.schema",
    "read_plan": "povlens.plan.schema",
    "PovlensError": "povlens.errors",
    "UsageError": "povlens.errors",
    "ParameterError": "povlens.errors",
    "LensFileError": "povlens.errors",
    "OpticsError": "povlens.errors",
    "PovrayError": "povlens.errors",
}

__all__ = sorted(_API) + ["__version__"]


def __getattr__(name: str):
    if name in _API:
        value = getattr(importlib.import_module(_API[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'povlens' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_API))
