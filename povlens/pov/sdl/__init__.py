"""POV-Ray's scene description language (SDL): reading a scene's camera and writing SDL text.

The reader follows a scene the way POV-Ray 3.7's parser does and returns the camera it
would use (:func:`parse_scene_camera`, in :mod:`povlens.pov.sdl.scene_camera`), in layers:
:mod:`~povlens.pov.sdl.lexer` (tokens), :mod:`~povlens.pov.sdl.directives` (``#include``,
``#if``, loops, macros; with :mod:`~povlens.pov.sdl.control_flow`,
:mod:`~povlens.pov.sdl.declarations`, :mod:`~povlens.pov.sdl.symbols` and
:mod:`~povlens.pov.sdl.include_paths`), :mod:`~povlens.pov.sdl.expressions` (with
:mod:`~povlens.pov.sdl.builtin_functions` and :mod:`~povlens.pov.sdl.values`),
:mod:`~povlens.pov.sdl.transforms`, :mod:`~povlens.pov.sdl.camera_block` (the
``camera { }`` block), :mod:`~povlens.pov.sdl.scene_reader` (statements) and
:mod:`~povlens.pov.sdl.errors`.  :mod:`~povlens.pov.sdl.writer` writes SDL literals and
fills the wrapper templates.

This module is the subpackage's front: modules outside it import from here only
(``tests/test_architecture.py`` checks it).
"""

from __future__ import annotations

from povlens.pov.sdl.scene_camera import (ASPECT_TOLERANCE, DEFAULT_CAMERA_NOTE, SceneCamera,
                                          SceneCameraError, parse_scene_camera)
from povlens.pov.sdl.writer import TEMPLATE_DIR, pov_string, pov_vector, read_template

__all__ = ["parse_scene_camera", "SceneCamera", "SceneCameraError", "DEFAULT_CAMERA_NOTE",
           "ASPECT_TOLERANCE", "TEMPLATE_DIR", "pov_string", "pov_vector", "read_template"]
