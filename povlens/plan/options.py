"""What a conversion is asked for: :class:`ConvertOptions` and the render methods.

The user's own POV-Ray options (``library_paths``, ``clock``, ``povray_options``) go
to every POV-Ray run of the scene: the depth probes, the views, the lens samples
(:func:`povray_options_of`); the plan records them (:class:`~povlens.plan.schema.Inputs`).
"""

from __future__ import annotations

import dataclasses

from povlens.pov.povray_options import PovrayOptions

__all__ = ["ConvertOptions", "METHODS", "povray_options_of", "with_povray_options_checked"]

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
    width: int = 640
    height: int = 480
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
    library_paths: tuple[str, ...] = ()  # POV-Ray's +L: folders for #include files
    clock: float | None = None         # POV-Ray's +K: the frame's clock (None: a still, 0)
    povray_options: tuple[str, ...] = ()  # further POV-Ray options, e.g. ("+A0.3",)
    ray_mesh: str = "field"            # mesh: "field" (coarse interpolated meshes, one pupil
                                       # point per sample) or "pixel" (a face per pixel)
    shift_mm: tuple[float, float] | None = None  # lens shift (x, y) in mm on the image
                                       # plane, +y moves the image up (lens.film); None: none
    aperture_blades: int | None = None  # iris blades N >= 3 (lens.aperture_shape); None: round
    blade_curvature: float = 0.0       # iris edges: 0 straight ... 1 round
    blade_rotation_deg: float = 0.0    # iris turn, counter-clockwise (0: a corner at the top)
    aperture_image: str | None = None  # grey-level mask image over the stop's disc
    dispersion: bool = False           # mesh: each lens sample at its own wavelength, from
                                       # the lens's Abbe numbers (povlens.lens.dispersion)


def povray_options_of(opts) -> PovrayOptions:
    """The user's POV-Ray options of a conversion or of a plan's inputs.

    Parameters
    ----------
    opts : :class:`ConvertOptions` or :class:`~povlens.plan.schema.Inputs` (both have
        ``library_paths``, ``clock`` and ``povray_options``).

    Returns
    -------
    PovrayOptions
        Checked (:class:`~povlens.pov.povray_options.PovrayOptions`): library paths
        absolute, the clock a float.

    Raises
    ------
    ParameterError
        A library path naming no folder (``library_paths``), a clock that is not a
        finite number (``clock``), or an option povlens controls (``povray_options``).
    """
    return PovrayOptions(library_paths=opts.library_paths, clock=opts.clock,
                         extra_options=opts.povray_options)


def with_povray_options_checked(opts: ConvertOptions) -> ConvertOptions:
    """``opts`` with its POV-Ray options checked and normalised as the plan stores
    them (:func:`povray_options_of`: absolute library paths, a float clock, tuples)."""
    checked = povray_options_of(opts)
    return dataclasses.replace(opts, library_paths=checked.library_paths, clock=checked.clock,
                               povray_options=checked.extra_options)
