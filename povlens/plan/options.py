"""What a conversion is asked for: :class:`ConvertOptions` and the render methods."""

from __future__ import annotations

import dataclasses

__all__ = ["ConvertOptions", "METHODS"]

#: Render methods: ``auto`` chooses one of the other three from measurements.
METHODS = ("auto", "pinhole", "focal-blur", "mesh")


@dataclasses.dataclass
class ConvertOptions:
    """What ``povlens convert`` needs (units: scene units unless named)."""

    scene: str
    lens: str
    focus: float | None                # distance from the camera location, scene units;
                                       # None: from the scene (povlens.plan.autofocus)
    outdir: str
    f_number: float | None = None
    stop_diameter_mm: float | None = None
    film_diagonal_mm: float = 35.0
    film_size_mm: tuple[float, float] | None = None
    units: str = "m"
    width: int = 160
    height: int = 120
    method: str = "mesh"
    samples: int = 16
    batch_size: int | None = None      # samples per POV-Ray process; None = N / cores
    seed: int = 0
    location: tuple[float, float, float] | None = None
    look_at: tuple[float, float, float] | None = None
    sky: tuple[float, float, float] = (0.0, 1.0, 0.0)
    real_focus: bool = True            # film at the real-ray focus (else thick lens)
    vignetting: bool = True            # composite keeps the lens's vignetting
    jitter: bool = True                # film points jittered within each pixel (box filter)
    tolerance_px: float = 0.5          # method "auto": error budget in pixels
    auto_samples: bool = True          # method "auto": the decision sets the sample count
    adaptive: bool = False             # mesh: fewer samples in sharp row bands (depth probe)
    speculate: bool = False            # method "auto": start the likely render while the
                                       # depth probe runs (povlens render; not convert/plan)
    focus_at: tuple[int, int] | None = None  # focus None: focus on what the depth probe sees
                                       # at output pixel (column, row), 0-based from top left
    focus_from: str | None = None      # where a resolved focus came from (None: the option)
