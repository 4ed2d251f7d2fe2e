"""The plan of a render folder (``OUTDIR/plan.json``): typed records, one reader, one writer.

A :class:`Plan` holds every input and derived number of a conversion
(:mod:`povlens.plan.convert`): the inputs, the focused lens, the film, where the
camera frame sits in the scene, the equivalent thin lens and what it gets wrong,
POV-Ray's camera and image size, the lens-sample batches and, for ``--method
auto``, the decision.  The render (:mod:`povlens.rendering`), the report and the
benchmarks read it with :func:`read_plan`; :func:`write_plan` writes it.

On disk the plan is one JSON object whose keys are the :class:`Plan` fields (in
that order) after ``"povlens_plan": SCHEMA_VERSION``.  JSON has no infinity:
infinite distances are written as ``null`` and read back as ``inf``.  A
``plan.json`` without the version key (as written before it was checked) is read
as version 1; another version is refused with the advice to convert again.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from povlens.errors import PovlensError
from povlens.lens.film import Film
from povlens.plan.render_folder import PLAN_FILE
from povlens.thinlens.model import EquivalentThinLens
from povlens.thinlens.model_error import ModelError
from povlens.util.files import write_text

__all__ = ["SCHEMA_VERSION", "PLAN_FILE", "Inputs", "LensSummary", "FocusSolution",
           "CameraPlacement", "PovrayCamera", "PovraySettings", "FocalBlurSettings",
           "Decision", "AdaptiveSampling", "DepthProbeRecord", "FieldMeshSettings", "Plan",
           "plan_path", "read_plan",
           "write_plan", "plan_json"]

#: Version of the plan.json layout; :func:`read_plan` refuses any other.
SCHEMA_VERSION = 1
#: The key of the version in plan.json.
VERSION_KEY = "povlens_plan"

Vector = tuple[float, float, float]


def _vector(v) -> Vector:
    return tuple(float(x) for x in v)


def _inf_if_none(v) -> float:
    """A distance read from JSON: ``null`` stands for infinity."""
    return math.inf if v is None else float(v)


def _json_ready(obj):
    """``obj`` with JSON's types: inf / NaN as None, tuples as lists."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_ready(v) for v in obj]
    return obj


def _film_dict(film: Film) -> dict:
    """plan.json's ``film``: the film's fields and pixel pitch; the lens shift only when
    set (plans before it read and write back unchanged)."""
    d = dataclasses.asdict(film) | {"pixel_pitch_mm": film.pixel_pitch_mm}
    if not film.shifted:
        del d["shift_x_mm"], d["shift_y_mm"]
    return d


def _fields_of(cls, d: dict, **converted) -> Any:
    """``cls`` from the keys of ``d`` that are its fields (missing ones keep their
    defaults), ``converted`` overriding; a required field missing raises KeyError."""
    kw = {}
    for f in dataclasses.fields(cls):
        if f.name in converted:
            kw[f.name] = converted[f.name]
        elif f.name in d:
            kw[f.name] = d[f.name]
        elif f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise KeyError(f.name)
    return cls(**kw)


@dataclasses.dataclass(frozen=True)
class Inputs:
    """What the conversion was given (scene units unless named), and how it resolved
    them: ``lens`` is the lens file's path, ``lens_sha256`` its contents' hash,
    ``method`` / ``samples`` the render method and lens-sample count rendered.
    ``requested_method``, ``tolerance_px`` and ``auto_samples`` are set (not None)
    when ``--method auto`` chose them.  ``focus_from`` says where ``focus`` came from
    (``"option"``, ``"focal_point"``, ``"look_at"``, ``"depth probe at centre"``,
    ``"depth probe at X,Y"``: :mod:`povlens.plan.autofocus`), ``focus_at`` the
    output pixel (column, row) focused on; both None in plans written before them.
    ``library_paths``, ``clock`` and ``povray_options`` are the user's POV-Ray options
    (:func:`povlens.plan.options.povray_options_of`), which every POV-Ray run of the
    folder gets (``make``, ``povlens render-batch``); written only when set, empty in
    plans written before them."""

    scene: str
    lens: str
    lens_sha256: str
    focus: float
    units: str
    f_number: float | None
    stop_diameter_mm: float | None
    film_diagonal_mm: float
    film_size_mm: tuple[float, float] | None
    width: int
    height: int
    method: str
    samples: int
    batch_size: int | None
    seed: int
    real_focus: bool = True
    vignetting: bool = True
    jitter: bool = True
    adaptive: bool = False
    camera_from: str = ""
    requested_method: str | None = None
    tolerance_px: float | None = None
    auto_samples: bool | None = None
    focus_from: str | None = None
    focus_at: tuple[int, int] | None = None
    library_paths: tuple[str, ...] = ()
    clock: float | None = None
    povray_options: tuple[str, ...] = ()
    ray_mesh: str | None = None
    shift_mm: tuple[float, float] | None = None
    #: The stop's shape (povlens.lens.aperture_shape): iris blades, their curvature and
    #: turn (degrees), the mask image's path and its contents' hash; None: round.
    aperture_blades: int | None = None
    blade_curvature: float | None = None
    blade_rotation_deg: float | None = None
    aperture_image: str | None = None
    aperture_image_sha256: str | None = None
    #: --dispersion: True when each lens sample is traced at its own wavelength
    #: (povlens.rendering.spectral); None: not asked, or not rendered (plan.notes say why).
    dispersion: bool | None = None
    #: Anamorphic lenses: whether the image is desqueezed (povlens.plan.anamorphic);
    #: None for a rotationally symmetric lens.
    desqueeze: bool | None = None

    #: Fields written only when set (--method auto's, the focus's source, the user's
    #: POV-Ray options, the kind of ray mesh: None in plans before field meshes, which
    #: render per-pixel meshes): a plan without them reads and writes back unchanged.
    AUTO_FIELDS = ("requested_method", "tolerance_px", "auto_samples", "focus_from", "focus_at",
                   "library_paths", "clock", "povray_options", "ray_mesh", "shift_mm",
                   "aperture_blades", "blade_curvature", "blade_rotation_deg", "aperture_image",
                   "aperture_image_sha256", "dispersion", "desqueeze")

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        for k in self.AUTO_FIELDS:
            if d[k] is None or d[k] == ():
                del d[k]
        return _json_ready(d)

    @classmethod
    def from_dict(cls, d: dict) -> "Inputs":
        size, at, clock = d.get("film_size_mm"), d.get("focus_at"), d.get("clock")
        shift = d.get("shift_mm")
        focus = math.inf if d["focus"] is None else d["focus"]   # null: infinity
        return _fields_of(cls, d, focus=focus,
                          film_size_mm=None if size is None else tuple(size),
                          shift_mm=None if shift is None else (float(shift[0]),
                                                               float(shift[1])),
                          focus_at=None if at is None else (int(at[0]), int(at[1])),
                          library_paths=tuple(str(p) for p in d.get("library_paths", ())),
                          clock=None if clock is None else float(clock),
                          povray_options=tuple(str(o) for o in d.get("povray_options", ())))


@dataclasses.dataclass(frozen=True)
class LensSummary:
    """The stopped-down lens: surface count, aperture stop (row, diameter mm),
    paraxial EFL (mm), f-number and entrance-pupil diameter (mm)."""

    surfaces: int
    stop_index: int
    stop_diameter_mm: float
    efl_mm: float
    f_number: float
    entrance_pupil_diameter_mm: float


@dataclasses.dataclass(frozen=True)
class FocusSolution:
    """Where the film sits for the focus: the focus distance from the camera location
    (= entrance pupil), the object plane's distance from the film, the film
    distance (rear vertex to film; real-ray focus unless ``--thick-lens-focus``),
    the thick-lens film distance, and the RMS spot of the real-ray focus (None
    without it).  All in mm."""

    focus_from_camera_mm: float
    object_distance_from_film_mm: float
    film_distance_mm: float
    thick_lens_film_distance_mm: float
    rms_spot_mm: float | None = None

    @classmethod
    def from_dict(cls, d: dict) -> "FocusSolution":
        return _fields_of(cls, d, focus_from_camera_mm=_inf_if_none(d["focus_from_camera_mm"]),
                          object_distance_from_film_mm=_inf_if_none(
                              d["object_distance_from_film_mm"]))


@dataclasses.dataclass(frozen=True)
class CameraPlacement:
    """Where the camera frame sits in the scene: world position of the film centre
    (scene units), the world images of camera x, y, z (unit vectors) and
    millimetres per scene unit (:class:`povlens.pupil.rays.ScenePlacement`)."""

    film_centre: Vector
    right: Vector
    up: Vector
    forward: Vector
    mm_per_unit: float

    @classmethod
    def from_dict(cls, d: dict) -> "CameraPlacement":
        return cls(_vector(d["film_centre"]), _vector(d["right"]), _vector(d["up"]),
                   _vector(d["forward"]), float(d["mm_per_unit"]))


@dataclasses.dataclass(frozen=True)
class PovrayCamera:
    """POV-Ray's perspective camera of the equivalent thin lens (scene units):
    ``location`` (the entrance pupil), ``direction``, ``right`` and ``up`` (their
    lengths set the field of view), the ``focal_blur`` aperture and focal
    distance (1e9 for infinity), and the horizontal field of view in degrees."""

    location: Vector
    direction: Vector
    right: Vector
    up: Vector
    aperture: float
    focal_distance: float
    hfov_deg: float

    @classmethod
    def from_dict(cls, d: dict) -> "PovrayCamera":
        return _fields_of(cls, d, **{k: _vector(d[k]) for k in ("location", "direction",
                                                                "right", "up")})


@dataclasses.dataclass(frozen=True)
class PovraySettings:
    """POV-Ray's version and the image size rendered (pixels): ``render_height`` is
    the film's plus ``drop_top_rows``, the rows the composite drops (the POV-Ray
    3.7.0.x mesh-camera row workaround, :func:`povlens.pov.mesh.render_size`);
    ``render_width`` the film's plus ``drop_right_columns`` (field meshes:
    :func:`povlens.pov.field_mesh.uv_model`)."""

    version: str
    render_width: int
    render_height: int
    drop_top_rows: int
    drop_right_columns: int = 0
    #: The lens samples read the radiosity samples of one pinhole pretrace
    #: (``RenderFolder.radiosity_cache``; :mod:`povlens.rendering.radiosity_cache`).
    radiosity_cache: bool = False
    #: The scene's photons settings as SDL text ("" none): the lens samples load one
    #: photon map shot with them (``RenderFolder.photon_map``;
    #: :mod:`povlens.rendering.photon_map`).
    photon_settings: str = ""
    #: Lens samples render one pass per run at the film's size (no interleave, no
    #: stack; :mod:`povlens.rendering.sample_stacks`): the scene reads ``image_width``
    #: / ``image_height`` outside its camera, or povlens cannot tell its radiosity
    #: pretrace (the key's name is its first reason).
    image_size_read: bool = False
    #: The scene's radiosity (pretrace_start, pretrace_end), fractions of the frame's
    #: larger side: a field pass laid out larger than the frame repeats them scaled to
    #: its size, so its pretrace is spaced on the scene as the frame's would be
    #: (:func:`povlens.pov.mesh.pretrace_block`); None: the scene's are kept as read.
    radiosity_pretrace: tuple[float, float] | None = None

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        if self.radiosity_pretrace is None:  # nor those before the scaled pretrace
            del d["radiosity_pretrace"]
        else:
            d["radiosity_pretrace"] = [float(v) for v in self.radiosity_pretrace]
        if not self.image_size_read:        # nor those before stacked samples
            del d["image_size_read"]
        if not self.drop_right_columns:     # plans before field meshes had none
            del d["drop_right_columns"]
        if not self.radiosity_cache:        # nor those before the shared radiosity
            del d["radiosity_cache"]
        if not self.photon_settings:        # nor those before the shared photon map
            del d["photon_settings"]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "PovraySettings":
        pretrace = d.get("radiosity_pretrace")
        return _fields_of(cls, d, radiosity_pretrace=None if pretrace is None
                          else (float(pretrace[0]), float(pretrace[1])))


@dataclasses.dataclass(frozen=True)
class FocalBlurSettings:
    """POV-Ray ``focal_blur`` sampling: at least ``min_samples`` and at most
    ``max_samples`` per pixel, more until the ``confidence`` / ``variance`` test
    passes (None: POV-Ray's defaults).  On disk ``min`` and ``max``."""

    min_samples: int
    max_samples: int
    confidence: float | None = None
    variance: float | None = None

    def to_dict(self) -> dict:
        return {"min": self.min_samples, "max": self.max_samples,
                "confidence": self.confidence, "variance": self.variance}

    @classmethod
    def from_dict(cls, d: dict) -> "FocalBlurSettings":
        return cls(d["min"], d["max"], d.get("confidence"), d.get("variance"))


@dataclasses.dataclass
class Decision:
    """What ``--method auto`` chose: the method, its lens samples, the reasons (one
    line each, the conclusion ``-> method: ...`` last) and the numbers behind
    them (measurements keyed by name, units in the names).  ``focal_blur``: the
    sampling of a chosen focal_blur; ``provisional``: a plan written before the
    depth probe was in (:mod:`povlens.plan.speculative`)."""

    method: str
    samples: int
    reasons: list[str]
    numbers: dict = dataclasses.field(default_factory=dict)
    focal_blur: FocalBlurSettings | None = None
    provisional: bool = False

    def add_remark(self, text: str) -> None:
        """Add a reason before the conclusion (which stays last: summaries print it)."""
        self.reasons.insert(max(len(self.reasons) - 1, 0), text)

    def to_dict(self) -> dict:
        d: dict = {"method": self.method, "samples": self.samples}
        if self.focal_blur is not None:
            d["focal_blur"] = self.focal_blur.to_dict()
        if self.provisional:
            d["provisional"] = True
        d["reasons"] = list(self.reasons)
        if self.numbers:
            d["numbers"] = self.numbers
        return _json_ready(d)

    @classmethod
    def from_dict(cls, d: dict) -> "Decision":
        fb = d.get("focal_blur")
        return cls(d["method"], d["samples"], list(d.get("reasons", [])),
                   dict(d.get("numbers", {})),
                   None if fb is None else FocalBlurSettings.from_dict(fb),
                   bool(d.get("provisional", False)))


@dataclasses.dataclass(frozen=True)
class AdaptiveSampling:
    """Adaptive mesh sampling (``--adaptive``): bands of ``band_rows`` film rows,
    each with its largest blur (px) and the lens samples it needs (at least
    ``n_min``); in a plan also the pixel-samples rendered and those of a uniform
    render with as many samples (:func:`povlens.plan.adaptive.adaptive_rows`)."""

    band_rows: int
    n_min: int
    band_blur_px: list[float]
    band_samples: list[int]
    pixel_samples: int | None = None
    uniform_pixel_samples: int | None = None

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return _json_ready({k: v for k, v in d.items() if v is not None})

    @classmethod
    def from_dict(cls, d: dict) -> "AdaptiveSampling":
        return _fields_of(cls, d, band_blur_px=list(d["band_blur_px"]),
                          band_samples=list(d["band_samples"]))


@dataclasses.dataclass(frozen=True)
class DepthProbeRecord:
    """The depth probes run for a plan (:mod:`povlens.plan.depth_probe`): ``method``
    (one line), ``treatment`` (how background and pixels without a depth of their own
    count), and the numbers of the probes: ``depth_range`` (the depth range of
    --method auto or --adaptive: pixels, background and no-depth counts, near / far)
    and ``focus`` (:mod:`povlens.plan.autofocus`: where the focus was measured and
    what the probe saw there).  Distances in mm unless named.  That the probe does
    not see the scene's fog or media is one of the plan's ``notes`` (earlier plans
    kept it here as ``scene_atmosphere``: :meth:`Plan.from_dict` moves it)."""

    method: str
    treatment: str
    depth_range: dict | None = None
    focus: dict | None = None

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return _json_ready({k: v for k, v in d.items() if v is not None})

    @classmethod
    def from_dict(cls, d: dict) -> "DepthProbeRecord":
        return _fields_of(cls, d)


@dataclasses.dataclass(frozen=True)
class FieldMeshSettings:
    """The field ray meshes of a mesh plan (:mod:`povlens.plan.field_grid`): ``grid``
    faces across and down, the direction encoding ``eps``, the pupil domain of every
    film point (``domain``: :class:`povlens.pupil.field_domain.FieldDomain` as a dict;
    ``pupil_disc_radius_mm`` the disc about the axis that holds every film point's
    region, for the record), ``interleave`` m (a pass renders m x m tiles, each pixel
    of a tile with the tile's lens sample: :func:`povlens.pov.field_mesh.pass_models`),
    and the certification: the largest ray error measured (``max_ray_error_px``, angle x
    focal length / pixel pitch; ``max_origin_error_mm``) over ``pupil_points`` pupil
    points and ``pixels_checked`` pixels each."""

    grid: tuple[int, int]
    eps: float
    pupil_disc_radius_mm: float
    max_ray_error_px: float
    max_origin_error_mm: float
    pupil_points: int
    pixels_checked: int
    limit_px: float
    domain: dict | None = None
    interleave: int = 1

    def to_dict(self) -> dict:
        return _json_ready(dataclasses.asdict(self))

    @classmethod
    def from_dict(cls, d: dict) -> "FieldMeshSettings":
        return _fields_of(cls, d, grid=(int(d["grid"][0]), int(d["grid"][1])),
                          interleave=int(d.get("interleave", 1)))


@dataclasses.dataclass
class Plan:
    """Everything a render folder is rendered from (see the module docstring).

    ``model_error`` is :func:`povlens.thinlens.model_error.measure_model_error` at the
    plan's standard depths (half, once, twice and ten times the focus distance; None:
    not measured, a pinhole plan's, written as ``{}``);
    ``sink_centre`` the world point (scene units) where the ray mesh parks blocked
    rays; ``batches`` the lens samples of each ``povlens render-batch``;
    ``sample_rows`` the film rows [start, end) of each sample when the sampling
    is adaptive (None: every sample renders the whole frame); ``depth_probe`` the
    depth probes run for it (None: none); ``notes`` what of the scene povlens replaces
    or ignores (its camera's projection, focal blur, ``normal``, proportions; its fog
    and media in the depth probe; options a render cannot use), one sentence each,
    printed once by the command line (empty: nothing, and not written);
    ``vignetting_map`` what the render of a pinhole or focal-blur view multiplied its
    image by for the lens's vignetting (:mod:`povlens.rendering.vignetting`; None:
    nothing, and not written); ``dispersion`` the lens's chromatic aberration with
    ``--dispersion`` (:mod:`povlens.plan.dispersion_plan`; None: not asked or no Abbe
    numbers, and not written); ``pixel_iris`` the iris domain of per-pixel meshes
    (:func:`povlens.plan.aperture.apply_aperture_shape`; None: no iris or other meshes,
    and not written)."""

    inputs: Inputs
    lens: LensSummary
    focus: FocusSolution
    film: Film
    mm_per_unit: float
    placement: CameraPlacement
    thin_lens: EquivalentThinLens
    povray_camera: PovrayCamera
    model_error: ModelError | None
    povray: PovraySettings
    sink_centre: Vector
    batches: list[list[int]]
    sample_rows: list[tuple[int, int]] | None = None
    adaptive: AdaptiveSampling | None = None
    decision: Decision | None = None
    depth_probe: DepthProbeRecord | None = None
    notes: list[str] = dataclasses.field(default_factory=list)
    vignetting_map: dict | None = None
    field_mesh: FieldMeshSettings | None = None
    #: --dispersion on a lens with Abbe numbers: its chromatic aberration
    #: (povlens.lens.dispersion.chromatic_aberration) and how the samples get colour.
    dispersion: dict | None = None
    #: per-pixel meshes with an iris: {domain_radius_mm, flip, disc_radius_mm} of the
    #: domain their sampler uses where it is tighter (povlens.pupil.iris_sampler).
    pixel_iris: dict | None = None
    #: an anamorphic lens: both meridians' first-order data, the squeeze, the desqueeze
    #: and the film's pixel aspect (povlens.plan.anamorphic.anamorphic_record).
    anamorphic: dict | None = None

    def add_note(self, text: str | None) -> None:
        """Add a note (:attr:`notes`) unless it is empty or already there."""
        if text and text not in self.notes:
            self.notes.append(text)

    def rows_of_sample(self, k: int) -> tuple[int, int]:
        """Film rows [start, end) lens sample ``k`` renders (all unless adaptive)."""
        if self.sample_rows is None:
            return 0, self.film.height_px
        r0, r1 = self.sample_rows[k]
        return int(r0), int(r1)

    def record_auto_choice(self, decision: Decision, tolerance_px: float,
                           auto_samples: bool) -> None:
        """Record that ``--method auto`` chose this plan.  ``inputs.method`` stays the
        method rendered (render, Makefile and report read it); ``requested_method``
        says it was chosen automatically."""
        self.inputs = dataclasses.replace(self.inputs, requested_method="auto",
                                          tolerance_px=tolerance_px, auto_samples=auto_samples)
        self.decision = decision

    def to_dict(self) -> dict:
        """The plan as plan.json holds it (JSON types, infinities as None)."""
        d = {VERSION_KEY: SCHEMA_VERSION,
             "inputs": self.inputs.to_dict(),
             "lens": dataclasses.asdict(self.lens),
             "focus": dataclasses.asdict(self.focus),
             "film": _film_dict(self.film),
             "mm_per_unit": self.mm_per_unit,
             "placement": dataclasses.asdict(self.placement),
             "thin_lens": self.thin_lens.to_dict(),
             "povray_camera": dataclasses.asdict(self.povray_camera),
             "model_error": {} if self.model_error is None else self.model_error.to_dict(),
             "povray": self.povray.to_dict(),
             "sink_centre": self.sink_centre,
             "batches": self.batches}
        if self.sample_rows is not None:
            d["sample_rows"] = self.sample_rows
        if self.adaptive is not None:
            d["adaptive"] = self.adaptive.to_dict()
        if self.decision is not None:
            d["decision"] = self.decision.to_dict()
        if self.depth_probe is not None:
            d["depth_probe"] = self.depth_probe.to_dict()
        if self.notes:
            d["notes"] = list(self.notes)
        if self.vignetting_map is not None:
            d["vignetting_map"] = self.vignetting_map
        if self.field_mesh is not None:
            d["field_mesh"] = self.field_mesh.to_dict()
        if self.dispersion is not None:
            d["dispersion"] = self.dispersion
        if self.pixel_iris is not None:
            d["pixel_iris"] = self.pixel_iris
        if self.anamorphic is not None:
            d["anamorphic"] = self.anamorphic
        return _json_ready(d)

    @classmethod
    def from_dict(cls, d: dict) -> "Plan":
        """The plan of a plan.json object (KeyError / TypeError / ValueError if it is
        not one)."""
        f, tl = d["film"], d["thin_lens"]
        rows, adaptive, decision = d.get("sample_rows"), d.get("adaptive"), d.get("decision")
        probe = d.get("depth_probe")
        notes = [str(n) for n in d.get("notes", [])]
        old_note = None if probe is None else probe.get("scene_atmosphere")
        if old_note and old_note not in notes:      # where plans before notes kept it
            notes.append(str(old_note))
        return cls(
            inputs=Inputs.from_dict(d["inputs"]),
            lens=_fields_of(LensSummary, d["lens"]),
            focus=FocusSolution.from_dict(d["focus"]),
            film=Film(f["width_mm"], f["height_mm"], int(f["width_px"]), int(f["height_px"]),
                      float(f.get("shift_x_mm", 0.0)), float(f.get("shift_y_mm", 0.0))),
            mm_per_unit=d["mm_per_unit"],
            placement=CameraPlacement.from_dict(d["placement"]),
            thin_lens=EquivalentThinLens(tl["centre_z_mm"], tl["image_distance_mm"],
                                         tl["pupil_diameter_mm"], _inf_if_none(tl["focus_z_mm"]),
                                         tl.get("fov_fit_rms_mm", 0.0),
                                         tl.get("image_distance_x_mm"),
                                         tl.get("pupil_diameter_x_mm")),
            povray_camera=PovrayCamera.from_dict(d["povray_camera"]),
            model_error=ModelError.from_dict(d["model_error"]) if d["model_error"] else None,
            povray=PovraySettings.from_dict(d["povray"]),
            sink_centre=_vector(d["sink_centre"]),
            batches=[[int(k) for k in b] for b in d["batches"]],
            sample_rows=None if rows is None else [(int(r[0]), int(r[1])) for r in rows],
            adaptive=None if adaptive is None else AdaptiveSampling.from_dict(adaptive),
            decision=None if decision is None else Decision.from_dict(decision),
            depth_probe=None if probe is None else DepthProbeRecord.from_dict(probe),
            notes=notes,
            field_mesh=None if d.get("field_mesh") is None
            else FieldMeshSettings.from_dict(d["field_mesh"]),
            vignetting_map=d.get("vignetting_map"), dispersion=d.get("dispersion"),
            pixel_iris=d.get("pixel_iris"), anamorphic=d.get("anamorphic"))


def plan_path(path: str | os.PathLike) -> Path:
    """The plan.json of ``path``: ``path`` itself if it names a ``.json`` file, else
    ``path / plan.json`` (a render folder)."""
    p = Path(path)
    return p if p.suffix == ".json" else p / PLAN_FILE


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


def plan_json(plan: Plan) -> str:
    """The text of ``plan``'s plan.json."""
    return json.dumps(plan.to_dict(), indent=2, allow_nan=False, default=_json_default) + "\n"


def read_plan(path: str | os.PathLike) -> Plan:
    """Read the plan of a render folder (or of a ``.json`` file).

    Parameters
    ----------
    path : the render folder, or the plan's JSON file.

    Returns
    -------
    Plan

    Raises :class:`~povlens.errors.PovlensError` (saying to run ``povlens convert``)
    when the file is missing, not JSON, of another schema version or not a plan.
    """
    path = plan_path(path)
    try:
        d = json.loads(path.read_text())
    except FileNotFoundError:
        raise PovlensError(f"{path} does not exist",
                           "run 'povlens convert SCENE --lens LENS --focus D -o OUTDIR' first"
                           ) from None
    except json.JSONDecodeError as e:
        raise PovlensError(f"{path}: not valid JSON ({e.msg}, line {e.lineno})",
                           "run 'povlens convert' again to rewrite it") from None
    if not isinstance(d, dict):
        raise PovlensError(f"{path} is not a povlens plan", "run 'povlens convert' again")
    if d.get(VERSION_KEY, SCHEMA_VERSION) != SCHEMA_VERSION:
        raise PovlensError(f"{path} was written by another version of povlens",
                           "run 'povlens convert' again")
    try:
        return Plan.from_dict(d)
    except (KeyError, TypeError, ValueError, IndexError) as e:
        raise PovlensError(f"{path} is not a plan this version of povlens can read "
                           f"({type(e).__name__}: {e})",
                           "run 'povlens convert' again to rewrite it") from None


def write_plan(plan: Plan, path: str | os.PathLike) -> Path:
    """Write ``plan`` to a render folder's plan.json (or to a ``.json`` file),
    atomically (:func:`povlens.util.files.write_text`).  An identical file is left
    alone: make compares modification times.  Returns the file's path."""
    path = plan_path(path)
    text = plan_json(plan)
    try:
        if path.read_text() == text:
            return path
    except OSError:
        pass
    return write_text(path, text)
