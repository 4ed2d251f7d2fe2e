"""The aperture stop's shape of a conversion: options -> :class:`ApertureShape`, plan.json.

``--aperture-blades N`` (with ``--blade-curvature``, ``--blade-rotation``) makes an iris,
``--aperture-image MASK.png`` a grey-level mask over the stop's disc
(:mod:`povlens.lens.aperture_shape`).  The mask image is read here, through
:mod:`povlens.util.images` (the lens layer reads no images), as stored values (no
linearisation: 0.5 grey transmits half), the mean of its colour channels (alpha ignored).
plan.json's ``inputs`` keep the shape and the mask file's hash, so
:func:`shape_of_inputs` rebuilds the same shape for the render (and refuses a changed mask).

Only the exact-ray method draws the shape: POV-Ray's ``focal_blur`` samples a round
aperture, so ``--method focal-blur`` renders it round (:data:`FOCAL_BLUR_NOTE`) and
``--method auto`` renders mesh whenever the blur is visible (:data:`AUTO_NOTE`).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from povlens.errors import ParameterError, PovlensError
from povlens.lens.aperture_shape import ApertureShape

__all__ = ["shape_of_options", "shape_of_inputs", "inputs_of_shape", "read_mask", "describe",
           "apply_aperture_shape", "band_iris_domain", "FOCAL_BLUR_NOTE", "AUTO_NOTE",
           "PINHOLE_NOTE"]

FOCAL_BLUR_NOTE = ("the aperture shape ({what}) is drawn only by the exact lens rays: "
                   "focal_blur renders a round aperture (use --method mesh)")
AUTO_NOTE = ("the aperture shape ({what}) is drawn only by the exact lens rays, so auto "
             "renders mesh where the blur is visible (focal_blur cannot draw it)")
PINHOLE_NOTE = ("the aperture shape ({what}) does not show: the blur is below the "
                "tolerance everywhere, so auto renders a pinhole view")


def _file_sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def read_mask(path) -> np.ndarray:
    """(H, W) float64 transmission of a mask image file (values as stored, 0..1).

    Raises ParameterError (``aperture_image``) for a missing, unreadable or non-image
    file, one-line messages naming it."""
    from povlens.util.images import ImageError, read_image
    p = Path(path)
    if not p.is_file():
        raise ParameterError("aperture_image", str(path),
                             f"aperture_image={path}: no such file", "check the path")
    try:
        img = read_image(p)
    except ImageError as e:
        raise ParameterError("aperture_image", str(path),
                             f"aperture_image={path}: not a readable image "
                             f"({e.message.splitlines()[0]})",
                             "give a grey-level PNG (white open, black opaque)") from None
    c = img.shape[2]
    colour = img[:, :, :3] if c >= 3 else img[:, :, :1]
    return np.asarray(colour, dtype=np.float64).mean(axis=2)


def _shape(blades, curvature, rotation_deg, image) -> ApertureShape | None:
    if blades is None and image is None:
        return None
    mask = read_mask(image) if image is not None else None
    return ApertureShape(blades=blades, curvature=0.0 if curvature is None else curvature,
                         rotation_deg=0.0 if rotation_deg is None else rotation_deg,
                         mask=mask, mask_source=str(image) if image is not None else "")


def shape_of_options(aperture) -> ApertureShape | None:
    """The shape asked for by :class:`~povlens.plan.options.ApertureOptions` (None:
    round).  ``blade_curvature`` / ``blade_rotation_deg`` without blades are refused
    (they would do nothing)."""
    if aperture.aperture_blades is None:
        for name in ("blade_curvature", "blade_rotation_deg"):
            v = getattr(aperture, name)
            if v not in (None, 0.0):
                raise ParameterError(name, v, f"{name}={v}: needs an iris",
                                     "give aperture_blades=N too")
    return _shape(aperture.aperture_blades, aperture.blade_curvature,
                  aperture.blade_rotation_deg, aperture.aperture_image)


def inputs_of_shape(shape: ApertureShape | None) -> dict:
    """The plan.json ``inputs`` fields of ``shape`` (empty for the round stop)."""
    if shape is None:
        return {}
    d: dict = {}
    if shape.blades is not None:
        d.update(aperture_blades=shape.blades, blade_curvature=shape.curvature,
                 blade_rotation_deg=shape.rotation_deg)
    if shape.mask is not None:
        p = Path(shape.mask_source).resolve()
        d.update(aperture_image=str(p), aperture_image_sha256=_file_sha256(p))
    return d


def shape_of_inputs(inputs) -> ApertureShape | None:
    """The shape a plan's :class:`~povlens.plan.schema.Inputs` recorded, read again;
    refused if the mask file changed since the conversion."""
    image = getattr(inputs, "aperture_image", None)
    if image is not None:
        p = Path(image)
        if not p.is_file() or _file_sha256(p) != inputs.aperture_image_sha256:
            raise PovlensError(f"the aperture mask {image} changed or is gone since "
                               "'povlens convert'", "run 'povlens convert' again")
    return _shape(getattr(inputs, "aperture_blades", None),
                  getattr(inputs, "blade_curvature", None),
                  getattr(inputs, "blade_rotation_deg", None), image)


def describe(shape: ApertureShape) -> str:
    """A few words for notes: '6 blades, curvature 0.2, turned 15 deg' / 'mask ring.png'."""
    parts = []
    if shape.blades is not None:
        parts.append(f"{shape.blades} blades" + (f", curvature {shape.curvature:g}"
                                                 if shape.curvature else "")
                     + (f", turned {shape.rotation_deg:g} deg" if shape.rotation_deg else ""))
    if shape.mask is not None:
        parts.append(f"mask {Path(shape.mask_source).name}")
    return "; ".join(parts)


def apply_aperture_shape(opts, plan, lens, table) -> None:
    """What a shaped stop changes in a finished plan: ``focal-blur`` gets
    :data:`FOCAL_BLUR_NOTE`; a per-pixel mesh plan of an iris gets ``plan.pixel_iris``
    (the iris's pupil domain, :func:`povlens.pupil.aperture_domain.iris_domain`, with
    ``--dispersion`` the one holding every wavelength's, :func:`band_iris_domain`; for
    :class:`povlens.pupil.iris_sampler.IrisPixelSampler`).  Field meshes draw from the
    round stop's ellipses, which hold the iris's regions
    (:mod:`povlens.pupil.field_domain`)."""
    shape = lens.aperture_shape
    if shape is None:
        return
    if opts.sampling.method == "focal-blur":
        plan.add_note(FOCAL_BLUR_NOTE.format(what=describe(shape)))
    fm = plan.field_mesh
    if (shape.blades is None or shape.mask is not None or table is None
            or plan.inputs.method != "mesh" or fm is not None
            or getattr(table, "kind", "radial") == "grid"):
        # field meshes: the ellipses of the round stop hold the iris's regions; an
        # anamorphic lens's per-pixel meshes draw from its grid table's, which hold them too
        return
    from povlens.pupil.aperture_domain import iris_domain
    from povlens.pupil.band_table import band_table
    from povlens.pupil.field import bounding_disc_radius_mm
    fd = plan.focus.film_distance_mm
    # per-pixel meshes with --dispersion draw from the band table (rendering.spectral)
    factors = (plan.dispersion or {}).get("pupil_dilation")
    grown = table if factors is None else band_table(table, factors)
    if getattr(plan.inputs, "dispersion", None):
        radius, flip = band_iris_domain(lens, fd, table, None if factors is None else grown)
    else:
        radius, flip, _ = iris_domain(lens, fd, table)
    # per-pixel meshes: the domain where it is tighter than the table
    plan.pixel_iris = {"domain_radius_mm": float(radius), "flip": bool(flip),
                       "disc_radius_mm": bounding_disc_radius_mm(grown)}


def band_iris_domain(lens, film_distance_mm: float, table, grown=None) -> tuple[float, bool]:
    """R_D (mm) and flip of the iris domain that holds the pass regions of the d line and
    of the band's ends (``--dispersion``): the largest of their
    :func:`~povlens.pupil.aperture_domain.iris_domain` radii, each searched over the
    round-stop table grown to hold the band (``grown``, default made here:
    :mod:`povlens.pupil.band_table`); the pupils change monotonically with the index, so
    the ends bound the band."""
    from povlens.lens.dispersion import BAND_NM, lens_at_wavelength
    from povlens.pupil.aperture_domain import iris_domain
    from povlens.pupil.band_table import band_dilation, band_table
    ends = [lens_at_wavelength(lens, lam) for lam in BAND_NM]
    if grown is None:
        grown = band_table(table, band_dilation(table, ends))
    radius, flip, _ = iris_domain(lens, film_distance_mm, grown)
    for end in ends:
        radius = max(radius, iris_domain(end, film_distance_mm, grown)[0])
    return radius, flip
