"""The errors of reading a scene's camera from POV-Ray scene description language (SDL).

:class:`SceneCameraError` is what callers see; :class:`SdlEvalError` is raised inside
the reader for one construct it cannot evaluate and becomes a :class:`SceneCameraError`
(or an unknown value) before it leaves :func:`povlens.pov.sdl.scene_camera.parse_scene_camera`.
"""

from __future__ import annotations

from povlens.errors import PovlensError

__all__ = ["SceneCameraError", "SdlEvalError", "MeshCameraError", "EXPLICIT_CAMERA_HINT",
           "with_explicit_hint"]

#: What to do when the scene's camera cannot be read: give it explicitly.
EXPLICIT_CAMERA_HINT = ("give the camera explicitly with 'location', 'look_at' and 'sky' (the "
                        "field of view follows from the lens and 'film_diagonal_mm' or "
                        "'film_size_mm')")


class SceneCameraError(PovlensError):
    """The scene's camera cannot be found or evaluated."""

    def __init__(self, message: str, hint: str | None = EXPLICIT_CAMERA_HINT):
        super().__init__(message, hint)


def with_explicit_hint(hint: str | None) -> str:
    """``hint`` (what to pass instead, may be empty), then :data:`EXPLICIT_CAMERA_HINT`."""
    return f"{hint}; or {EXPLICIT_CAMERA_HINT}" if hint else EXPLICIT_CAMERA_HINT


class SdlEvalError(Exception):
    """An SDL expression or camera item povlens cannot evaluate (the message names what
    and where, as ``file:line: ...``; ``hint``, if any, what to pass instead)."""

    def __init__(self, message: str, hint: str = ""):
        super().__init__(message)
        self.hint = hint


class MeshCameraError(SdlEvalError):
    """The camera is a ``mesh_camera``: its rays come from a mesh, it has no pose."""
