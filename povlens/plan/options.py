"""Every option of a conversion, declared once: :class:`ConvertOptions` and its records.

An option is a field of one of six small records (:class:`Pose`, :class:`FilmOptions`,
:class:`ApertureOptions`, :class:`Sampling`, :class:`AutoOptions`,
:class:`PovrayPassthrough`); its declaration (:func:`option`) holds everything about it:
name (the API keyword and the plan's ``inputs`` key), type, default, unit, help, the
command-line flag and how the flag sets it, and the check of its value.  From the
records are derived

* the command line's arguments (:mod:`povlens.cli.render_cmd` walks :func:`options`),
* the flag of each parameter in error messages (:mod:`povlens.cli.flags`),
* the API's keyword checking (:meth:`ConvertOptions.of`),
* the plan's ``inputs`` (:func:`stored_values`).

Values are checked when a record is made (its ``__post_init__``), however it is made:
a value that cannot work raises :class:`~povlens.errors.ParameterError` naming the
option.  What depends on the scene or the lens (a sky parallel to the view, blades
without an iris) is checked where that is known.

The user's own POV-Ray options (``library_paths``, ``clock``, ``povray_options``) go
to every POV-Ray run of the scene: the depth probes, the views, the lens samples
(:func:`povray_options_of`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator
from typing import Any

from povlens.errors import ParameterError
from povlens.lens.film import DEFAULT_FILM_DIAGONAL_MM, parse_film_size, parse_shift
from povlens.lens.focus import UNITS_MM
from povlens.pov.povray_options import PovrayOptions

__all__ = ["ConvertOptions", "Pose", "FilmOptions", "ApertureOptions", "Sampling",
           "AutoOptions", "PovrayPassthrough", "DaskOptions", "dask_options", "OptionSpec",
           "option", "options", "RECORDS",
           "METHODS", "FIXED_SAMPLES", "povray_options_of", "stored_values",
           "parse_vector", "parse_pixel", "parse_clock", "with_povray_options_checked",
           "SCHEDULER_ENV_VAR"]

#: Render methods: ``auto`` chooses one of the other three from measurements.
METHODS = ("auto", "pinhole", "focal-blur", "mesh")
#: Lens samples of a fixed method when ``samples`` is not given.
FIXED_SAMPLES = 16


# --- parsing command-line text (argparse types: ValueError carries the message) -----

def parse_vector(text: str) -> tuple[float, float, float]:
    """``X,Y,Z`` (angle brackets allowed) -> a 3-vector."""
    try:
        v = tuple(float(t) for t in text.replace("<", "").replace(">", "").split(","))
    except ValueError:
        v = ()
    if len(v) != 3:
        raise ValueError(f"'{text}' is not a vector x,y,z")
    return v


def parse_pixel(text: str) -> tuple[int, int]:
    """``X,Y``: the 0-based column and row of an output pixel."""
    try:
        x, y = (int(t) for t in text.split(","))
    except ValueError:
        raise ValueError(f"'{text}' is not a pixel X,Y (column, row: whole numbers "
                         f"from 0)") from None
    if x < 0 or y < 0:
        raise ValueError(f"'{text}': the column and row count from 0")
    return x, y


def parse_clock(text: str) -> float:
    """A finite number: POV-Ray's clock."""
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"'{text}' is not a number") from None
    if not math.isfinite(v):
        raise ValueError(f"'{text}' must be a finite number")
    return v


# --- checks of values: (name, value) -> the value as stored, or ParameterError -------

Check = Callable[[str, Any], Any]


def _number(name: str, value, kind=float):
    try:
        v = kind(value)
    except (TypeError, ValueError):
        raise ParameterError(name, value, f"{name}={value!r}: not a number") from None
    if kind is int and v != value:
        raise ParameterError(name, value, f"{name}={value!r}: must be a whole number")
    if not math.isfinite(v):
        raise ParameterError(name, value, f"{name}={value!r}: must be a finite number")
    return v


def positive(name: str, value) -> float:
    v = _number(name, value)
    if not v > 0:
        raise ParameterError(name, value, f"{name}={value}: must be positive")
    return v


def distance(name: str, value) -> float:
    """A positive distance in scene units; ``inf`` (focus at infinity) is one."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(name, value, f"{name}={value!r}: not a number") from None
    if not v > 0:
        raise ParameterError(name, value, f"{name}={value}: must be a positive distance in "
                                          f"scene units (inf: infinity)")
    return v


def finite(name: str, value) -> float:
    return _number(name, value)


def whole(name: str, value) -> int:
    return _number(name, value, int)


def at_least_one(name: str, value) -> int:
    v = _number(name, value, int)
    if v < 1:
        raise ParameterError(name, value, f"{name}={value}: must be at least 1")
    return v


def flag(name: str, value) -> bool:
    if not isinstance(value, bool):
        raise ParameterError(name, value, f"{name}={value!r}: must be True or False")
    return value


def one_of(*choices: str) -> Check:
    def check(name: str, value) -> str:
        if value not in choices:
            raise ParameterError(name, value, f"{name}={value!r}: unknown value",
                                 f"use one of {', '.join(choices)}")
        return value
    return check


def vector(name: str, value) -> tuple[float, float, float]:
    v = parse_vector(value) if isinstance(value, str) else value
    try:
        v = tuple(float(x) for x in v)
    except (TypeError, ValueError):
        v = ()
    if len(v) != 3 or not all(map(math.isfinite, v)):
        raise ParameterError(name, value, f"{name}={value!r}: must be a vector of three "
                                          f"finite numbers")
    return v


def pixel(name: str, value) -> tuple[int, int]:
    try:
        v = parse_pixel(value) if isinstance(value, str) else tuple(int(x) for x in value)
    except (TypeError, ValueError):
        v = ()
    if len(v) != 2 or min(v) < 0:
        raise ParameterError(name, value, f"{name}={value!r}: not a pixel (column, row), "
                                          f"0-based")
    return v


def film_size(name: str, value) -> tuple[float, float]:
    return parse_film_size(value if isinstance(value, str) else ",".join(map(str, value)))


def shift(name: str, value) -> tuple[float, float]:
    return parse_shift(value)


def text_path(name: str, value) -> str:
    return str(value)


def texts(name: str, value) -> tuple[str, ...]:
    """A tuple of texts; one text is one item (``library_paths="inc"``: one folder)."""
    if isinstance(value, str):
        return (value,)
    try:
        return tuple(str(v) for v in value)
    except TypeError:
        raise ParameterError(name, value, f"{name}={value!r}: give a text or a list of "
                                          f"texts") from None


# --- the declaration -------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class OptionSpec:
    """What the command line and the plan need to know of one option.

    ``flag``: the command-line option (None: API only).  ``sets``: how the flag sets
    the value: ``"value"`` (takes one), ``"append"`` (repeatable, a tuple),
    ``"true"`` (a switch setting True), ``"false"`` (a switch setting False, e.g.
    ``--no-jitter``), ``"both"`` (``--x`` / ``--no-x``).  ``parse``: command-line
    text to value (None: the text itself).  ``check``: ``(name, value)`` -> the value
    as stored, raising :class:`~povlens.errors.ParameterError`; not run on None.
    ``stored``: written to the plan's ``inputs`` as given.  ``exclusive``: options
    sharing it cannot be given together.
    """

    help: str
    flag: str | None = None
    sets: str = "value"
    parse: Callable[[str], Any] | None = None
    check: Check | None = None
    unit: str | None = None
    metavar: str | None = None
    choices: tuple | None = None
    stored: bool = True
    exclusive: str | None = None


def option(default, help: str, **spec) -> Any:
    """A record field that is an option (:class:`OptionSpec` fields as keywords)."""
    return dataclasses.field(default=default, metadata={"option": OptionSpec(help, **spec)})


class _Record:
    """Base of the option records: every option's value is checked when made."""

    #: Title of the record's options in ``--help`` (None: with the main options).
    TITLE: str | None = None

    def __post_init__(self):
        for f in dataclasses.fields(self):
            spec = f.metadata.get("option")
            value = getattr(self, f.name)
            if spec is not None and spec.check is not None and value is not None:
                object.__setattr__(self, f.name, spec.check(f.name, value))


@dataclasses.dataclass(frozen=True)
class Pose(_Record):
    """Where the camera is, what it looks at and focuses on (scene units)."""

    focus: float | None = option(
        None, "distance from the camera location to the plane in focus, inf for infinity "
        "(default: the scene "
        "camera's focal_point if it has focal blur, else the distance to its look_at, else "
        "what the depth probe sees at the centre of the frame); convert/render: A:B with "
        "--frames N is a focus pull from A to B (even steps in dioptres), D1,D2,... one "
        "frame per distance", flag="--focus", metavar="DIST", check=distance,
        unit="scene units", exclusive="focus", stored=False)
    focus_at: tuple[int, int] | None = option(
        None, "focus on what the depth probe sees at output pixel X,Y (column and row from "
        "the top left, 0-based; the median distance of the surface under it in a 5x5 pixel "
        "window)", flag="--focus-at", parse=parse_pixel, check=pixel, metavar="X,Y",
        unit="px", exclusive="focus", stored=False)
    units: str = option("m", "what one scene unit is", flag="--units",
                        choices=tuple(sorted(UNITS_MM)), check=one_of(*sorted(UNITS_MM)))
    location: tuple[float, float, float] | None = option(
        None, "camera location (instead of the scene's camera)", flag="--location",
        parse=parse_vector, check=vector, metavar="X,Y,Z", unit="scene units", stored=False)
    look_at: tuple[float, float, float] | None = option(
        None, "camera look_at point", flag="--look-at", parse=parse_vector, check=vector,
        metavar="X,Y,Z", unit="scene units", stored=False)
    sky: tuple[float, float, float] = option(
        (0.0, 1.0, 0.0), "camera sky vector", flag="--sky", parse=parse_vector,
        check=vector, metavar="X,Y,Z", stored=False)
    #: Where a resolved ``focus`` came from (None: the option); set by the conversion.
    focus_from: str | None = None


@dataclasses.dataclass(frozen=True)
class FilmOptions(_Record):
    """The image and the film behind the lens."""

    width: int = option(640, "image width in pixels", flag="--width", parse=int,
                        check=at_least_one, unit="px")
    height: int = option(480, "image height in pixels", flag="--height", parse=int,
                         check=at_least_one, unit="px")
    film_diagonal_mm: float = option(
        DEFAULT_FILM_DIAGONAL_MM, "film diagonal in mm; the film takes the image's aspect",
        flag="--film-diagonal", parse=float, check=positive, metavar="MM", unit="mm")
    film_size_mm: tuple[float, float] | None = option(
        None, "film width and height in mm instead", flag="--film-size", check=film_size,
        metavar="W,H", unit="mm")
    shift_mm: tuple[float, float] | None = option(
        None, "lens shift in mm on the film: the frame's centre moves X right and Y up off "
        "the lens axis (+Y shows more of the scene above, a view camera's rising front), so "
        "verticals stay vertical; beyond the lens's image circle the corners go dark",
        flag="--shift-mm", check=shift, metavar="X,Y", unit="mm", stored=False)
    real_focus: bool = option(
        True, "place the film by the thick-lens equation, not the real-ray focus",
        flag="--thick-lens-focus", sets="false", check=flag)
    desqueeze: bool = option(
        True, "anamorphic lenses: the image as a projector with the matching anamorphic lens "
        "shows it (the film sampled with pixels 'squeeze' times as tall as wide, no "
        "resampling); --no-desqueeze: the film as exposed, squeezed (povlens.plan.anamorphic)",
        flag="--desqueeze", sets="both", check=flag, stored=False)


@dataclasses.dataclass(frozen=True)
class ApertureOptions(_Record):
    """The aperture stop: its size, and its shape (:mod:`povlens.lens.aperture_shape`)."""

    TITLE = "aperture shape (the exact-ray methods draw it; focal_blur cannot)"

    f_number: float | None = option(None, "stop down to f/N", flag="--f-number", parse=float,
                                    check=positive, metavar="N", exclusive="stop")
    stop_diameter_mm: float | None = option(
        None, "aperture-stop diameter in mm", flag="--stop-diameter", parse=float,
        check=positive, metavar="MM", unit="mm", exclusive="stop")
    aperture_blades: float | None = option(
        None, "an iris of N >= 3 straight blades inscribed in the stop's circle (the "
        "f-number is the circle's)", flag="--aperture-blades", parse=float, check=finite,
        metavar="N", stored=False)
    blade_curvature: float = option(
        0.0, "blade edges from 0 straight to 1 round", flag="--blade-curvature",
        parse=float, check=finite, metavar="K", stored=False)
    blade_rotation_deg: float = option(
        0.0, "turn the iris counter-clockwise in degrees (0: a corner at the top)",
        flag="--blade-rotation", parse=float, check=finite, metavar="DEG", unit="deg",
        stored=False)
    aperture_image: str | None = option(
        None, "a grey-level mask over the stop's disc (white open, black opaque; grey "
        "transmits part); the image spans the stop's diameter", flag="--aperture-image",
        check=text_path, metavar="MASK.png", stored=False)


@dataclasses.dataclass(frozen=True)
class Sampling(_Record):
    """How the lens is rendered: the method, its lens samples and the composite."""

    method: str = option(
        "auto", "auto (the cheapest method within --tolerance, decided from a depth probe of "
        "the scene and the measured model error), pinhole, focal-blur (equivalent thin "
        "lens) or mesh (exact lens rays per sample)", flag="--method", choices=METHODS,
        check=one_of(*METHODS))
    samples: int | None = option(
        None, "lens samples per pixel (mesh renders, or focal_blur's blur_samples); "
        f"default: chosen by --method auto, else {FIXED_SAMPLES}", flag="--samples",
        parse=int, check=at_least_one, stored=False)
    batch_size: int | None = option(
        None, "lens samples per POV-Ray process (default: samples / cores, so each core "
        "runs one process)", flag="--batch-size", parse=int, check=at_least_one)
    seed: int = option(0, "seed of the sample sequence", flag="--seed", parse=int, check=whole)
    jitter: bool = option(
        True, "trace every pixel from its centre (no sub-pixel box filter), as POV-Ray's "
        "perspective camera without anti-aliasing does", flag="--no-jitter", sets="false",
        check=flag)
    vignetting: bool = option(
        True, "composite without the lens's vignetting (each pixel divided by its mean "
        "sample weight), for comparison with POV-Ray's own cameras", flag="--no-vignetting",
        sets="false", check=flag)
    adaptive: bool = option(
        False, "mesh renders: from a depth probe, give sharp row bands fewer lens samples "
        "than bands deep in blur (later samples render only the blurred rows, POV-Ray "
        "+SR/+ER); off by default: each partial sample still costs a POV-Ray run and a "
        "full mesh, so on the bundled scenes it saved no time at equal error",
        flag="--adaptive", sets="both", check=flag)
    ray_mesh: str = option(
        "field", "mesh renders: field (a coarse interpolated ray mesh per lens sample, one "
        "pupil point for the whole frame, rays within 0.05 px of the exact ones, measured) "
        "or pixel (a mesh face per pixel, each pixel its own pupil point; slower, kept for "
        "comparison)", flag="--ray-mesh", choices=("field", "pixel"),
        check=one_of("field", "pixel"), stored=False)
    dispersion: bool = option(
        False, "mesh renders: trace each lens sample at its own wavelength (from the lens "
        "file's Abbe numbers, 5th column) and composite through the CIE 1931 "
        "colour-matching functions: lateral and longitudinal colour", flag="--dispersion",
        sets="true", check=flag, stored=False)

    yes: bool = option(
        False, "go on with a request far beyond the usual (lens samples, image size, lens "
        "surfaces; povlens.plan.request_size) after saying what it costs; without it such "
        "a request stops with exit 2", flag="--yes", sets="true", check=flag, stored=False)

    @property
    def auto_samples(self) -> bool:
        """True when ``--method auto`` sets the sample count (``samples`` not given)."""
        return self.samples is None

    @property
    def sample_count(self) -> int:
        """The lens samples of a fixed method: ``samples``, else :data:`FIXED_SAMPLES`."""
        return FIXED_SAMPLES if self.samples is None else self.samples


@dataclasses.dataclass(frozen=True)
class AutoOptions(_Record):
    """What ``--method auto`` may spend (:mod:`povlens.plan.decision`)."""

    tolerance_px: float = option(0.5, "error budget of --method auto, in pixels",
                                 flag="--tolerance", parse=float, check=positive,
                                 metavar="PX", unit="px", stored=False)
    #: ``povlens render``: start the likely render while the depth probe runs
    #: (:mod:`povlens.plan.speculative`); set by the render driver, not an option.
    speculate: bool = False


@dataclasses.dataclass(frozen=True)
class PovrayPassthrough(_Record):
    """POV-Ray's own options, given to every POV-Ray run of the scene and kept in the
    plan (``make`` and ``render-batch`` use them)."""

    TITLE = "POV-Ray options (every POV-Ray run of the scene; kept in plan.json)"

    library_paths: tuple[str, ...] = option(
        (), "a folder where POV-Ray looks for #include files and image maps, as its +L "
        "(repeatable; after the scene's own folder)", flag="--library-path", sets="append",
        check=texts, metavar="DIR", stored=False)
    clock: float | None = option(
        None, "POV-Ray's clock for the frame, as its +K (default: a still, clock 0); the "
        "scene's camera is read at it too", flag="--clock", parse=parse_clock, check=finite,
        metavar="V", stored=False)
    povray_options: tuple[str, ...] = option(
        (), "a further POV-Ray switch or INI option, e.g. +A0.3 or Jitter=off (repeatable; "
        "write --povray-option=-J for one starting with '-'); options povlens sets itself "
        "(image size, output, display, threads, animation) are refused; mesh lens samples "
        "ignore anti-aliasing", flag="--povray-option", sets="append", check=texts,
        metavar="OPT", stored=False)


#: ConvertOptions field -> its record, in the order of ``--help``.
RECORDS = {"pose": Pose, "film": FilmOptions, "aperture": ApertureOptions,
           "sampling": Sampling, "auto": AutoOptions, "povray": PovrayPassthrough}


def options() -> Iterator[tuple[str, dataclasses.Field, OptionSpec]]:
    """Every option: (record field of :class:`ConvertOptions`, field, spec)."""
    for group, record in RECORDS.items():
        for f in dataclasses.fields(record):
            if "option" in f.metadata:
                yield group, f, f.metadata["option"]


#: option name -> its record field of ConvertOptions (``"width"`` -> ``"film"``); also
#: the records' plain fields (``focus_from``, ``speculate``), which a conversion sets.
_GROUP_OF = {f.name: group for group, record in RECORDS.items()
             for f in dataclasses.fields(record)}


@dataclasses.dataclass(frozen=True)
class ConvertOptions:
    """What ``povlens convert`` needs: the scene, the lens, the output folder and the
    option records.  Make one with :meth:`of` (flat keywords, checked); change one with
    :meth:`replace`."""

    scene: str
    lens: str
    outdir: str
    pose: Pose = Pose()
    film: FilmOptions = FilmOptions()
    aperture: ApertureOptions = ApertureOptions()
    sampling: Sampling = Sampling()
    auto: AutoOptions = AutoOptions()
    povray: PovrayPassthrough = PovrayPassthrough()

    @classmethod
    def of(cls, scene, lens, outdir, **values) -> "ConvertOptions":
        """Options from flat keywords (``width=320, f_number=8, ...``: any option's name).

        Raises
        ------
        ParameterError
            An unknown keyword (the message lists the known ones), or a value its
            option's check refuses.
        """
        unknown = sorted(set(values) - set(_GROUP_OF))
        if unknown:
            known = sorted(f.name for _, f, _ in options())
            raise ParameterError(unknown[0], values[unknown[0]],
                                 f"{unknown[0]!r} is not an option of a conversion",
                                 f"known options: {', '.join(known)}")
        return cls(str(scene), str(lens), str(outdir)).replace(**values)

    def replace(self, **values) -> "ConvertOptions":
        """A copy with the named options (or ``scene``, ``lens``, ``outdir``) changed."""
        top = {k: str(values.pop(k)) for k in ("scene", "lens", "outdir") if k in values}
        for group in RECORDS:
            mine = {k: v for k, v in values.items() if _GROUP_OF.get(k) == group}
            if mine:
                top[group] = dataclasses.replace(getattr(self, group), **mine)
                values = {k: v for k, v in values.items() if k not in mine}
        if values:
            raise TypeError(f"not options of a conversion: {', '.join(sorted(values))}")
        return dataclasses.replace(self, **top)

    def value(self, name: str):
        """The value of the option ``name`` (``"width"``)."""
        return getattr(getattr(self, _GROUP_OF[name]), name)


#: The environment variable naming the Dask scheduler when ``--scheduler`` is not given.
SCHEDULER_ENV_VAR = "POVLENS_SCHEDULER"


@dataclasses.dataclass(frozen=True)
class DaskOptions(_Record):
    """Where ``povlens render`` renders the lens samples: here, or on a Dask cluster
    (:mod:`povlens.cluster`).  Not part of the plan: the same folder renders either way."""

    TITLE = "distributed rendering (Dask; pip install 'povlens[distributed]')"

    #: An address, or (through the API) a ``distributed.Client`` the caller keeps.
    scheduler: str | object | None = option(
        None, "render the lens samples on the Dask cluster of this scheduler "
        "(tcp://HOST:8786; default: $POVLENS_SCHEDULER, else this machine); the workers "
        "need POV-Ray and povlens; the scene's folder (include files, image maps) is sent "
        "to them", flag="--scheduler", metavar="ADDRESS")
    shared_dir: bool = option(
        False, "with --scheduler: the workers see the scene, lens and OUTDIR at the same "
        "paths (a shared filesystem), so nothing is sent and they write the samples in "
        "place", flag="--shared-dir", sets="true", check=flag)
    scheduler_timeout_s: float = option(
        10.0, "seconds to wait for the scheduler to answer", flag="--scheduler-timeout",
        parse=float, check=positive, metavar="S", unit="s")
    group_size: int | None = option(
        None, "with --scheduler: lens samples per task, summed on the worker (default: the "
        "larger of samples/(2 workers) and sqrt(samples/2), at most 16; 1: each sample comes "
        "back, the image bit for bit the local one)", flag="--group-size", parse=int,
        check=at_least_one, metavar="N")


def dask_options() -> Iterator[tuple[dataclasses.Field, OptionSpec]]:
    """The options of :class:`DaskOptions`: (field, spec)."""
    for f in dataclasses.fields(DaskOptions):
        yield f, f.metadata["option"]


def stored_values(opts: ConvertOptions) -> dict:
    """The options the plan's ``inputs`` keep as given (those declared ``stored``);
    the others are kept as the conversion resolved them (:mod:`povlens.plan.plan_finish`)."""
    return {f.name: opts.value(f.name) for _, f, spec in options() if spec.stored}


def with_povray_options_checked(opts: ConvertOptions) -> ConvertOptions:
    """``opts`` with its POV-Ray options checked and normalised as the plan stores
    them (:func:`povray_options_of`: absolute library paths, a float clock, tuples)."""
    checked = povray_options_of(opts.povray)
    return opts.replace(library_paths=checked.library_paths, clock=checked.clock,
                        povray_options=checked.extra_options)


def povray_options_of(opts) -> PovrayOptions:
    """The user's POV-Ray options of a conversion or of a plan's inputs.

    Parameters
    ----------
    opts : :class:`PovrayPassthrough` or :class:`~povlens.plan.schema.Inputs` (both
        have ``library_paths``, ``clock`` and ``povray_options``).

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
