"""The data povlens ships: bundled lenses, POV-Ray templates and scenes.

They live in the package (``povlens/data/``; the repository's top-level ``lenses/``,
``templates/`` and ``scenes/`` are links to them) and are found through
:mod:`importlib.resources`, so an installed wheel finds them from any folder.
"""

from __future__ import annotations

import importlib.resources
from pathlib import Path

__all__ = ["data_folder", "LENS_DIR", "TEMPLATE_DIR", "SCENE_DIR", "bundled_scene",
           "resolve_scene_path"]


def data_folder(kind: str) -> Path:
    """The folder of bundled ``kind`` (``"lenses"``, ``"templates"`` or ``"scenes"``)."""
    return Path(str(importlib.resources.files("povlens.data").joinpath(kind)))


#: Bundled lens files (``*.dat``) and their sources (``SOURCES.md``).
LENS_DIR = data_folder("lenses")
#: POV-Ray wrapper, batch and Makefile templates.
TEMPLATE_DIR = data_folder("templates")
#: Bundled example scenes (``paper.pov``, ``chart.pov``).
SCENE_DIR = data_folder("scenes")


def bundled_scene(name: str) -> Path | None:
    """The bundled scene called ``name`` (``"paper"`` or ``"paper.pov"``), or None."""
    if "/" in name or "\\" in name:
        return None
    path = SCENE_DIR / (name if name.endswith(".pov") else f"{name}.pov")
    return path if path.is_file() else None


def resolve_scene_path(scene: str) -> str:
    """``scene`` as given when it exists (or names no bundled scene), else the path of
    the bundled scene of that name: ``povlens render paper ...`` works from any folder."""
    if Path(scene).exists():
        return scene
    bundled = bundled_scene(str(scene))
    return str(bundled) if bundled is not None else scene
