"""Requests far beyond the usual: what they would cost, said before the work starts.

A typo (``--samples 100000``, ``--width 64000``) or a lens file that is not a lens
(10,000 surfaces) would start hours of work, or exhaust memory, without a word.
:func:`check_request_size` compares a conversion's lens samples, pixels and lens
surfaces with :data:`LIMITS` and, beyond one, says what the request would cost: the
expected time of the lens samples at :data:`SECONDS_PER_PIXEL_SAMPLE`, the memory of
the composite, the tracing time measured on the lens itself.  Without ``--yes``
(``Sampling.yes``) the conversion stops there (a :class:`BigRequestError`, exit 2);
with it the same text is a :class:`BigRequestWarning` and the work goes on.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings

from povlens.errors import PovlensWarning, UsageError
from povlens.lens.focus import rms_spot_mm
from povlens.lens.paraxial import paraxial_data
from povlens.lens.prescription import LensPrescription

__all__ = ["LIMITS", "SECONDS_PER_PIXEL_SAMPLE", "BigRequestError", "BigRequestWarning",
           "Limits", "check_request_size", "request_costs"]


@dataclasses.dataclass(frozen=True)
class Limits:
    """What is still usual: beyond any of these povlens asks for ``--yes``."""

    samples: int = 1024                  # lens samples per pixel (auto picks 8 to 256)
    pixels: int = 7680 * 4320            # 8K UHD
    surfaces: int = 200                  # real lenses: about 40 at most
    hours: float = 2.0                   # expected time of the lens samples
    seconds_beyond_samples: float = 60.0  # beyond ``samples``, asked only above this


LIMITS = Limits()

#: POV-Ray's time per pixel and lens sample, s: povray-examples' advanced/woodbox.pov,
#: 320x240, --method mesh, 16 and 48 samples: 8.9 s and 13.9 s, so 2.0e-6 s for each
#: of the 32 x 76,800 further pixel-samples (2 cores, shared); a simple scene is
#: faster, a scene with radiosity or media much slower, so the figure is "about".
SECONDS_PER_PIXEL_SAMPLE = 2.0e-6

#: Bytes of the composite per pixel: float32 RGBA image, weights and a few work arrays.
COMPOSITE_BYTES_PER_PIXEL = 8 * 4 * 4

#: Bundles of rays focusing a lens traces through it (:func:`povlens.lens.focus.focus`
#: on dgauss.50mm: 119, each as :func:`~povlens.lens.focus.rms_spot_mm` traces it).
_TRACES_TO_FOCUS = 120


class BigRequestError(UsageError):
    """A request far beyond the usual, made without ``--yes``."""


class BigRequestWarning(PovlensWarning):
    """A request far beyond the usual, made with ``--yes``: the work goes on."""


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def _bytes(n: float) -> str:
    return f"{n / 2**30:.1f} GiB" if n >= 2**30 else f"{n / 2**20:.0f} MiB"


def _seconds_per_bundle(lens: LensPrescription) -> float:
    """Time (s) to trace through ``lens`` one of the bundles focusing traces."""
    p = paraxial_data(lens)
    start = time.perf_counter()
    rms_spot_mm(lens, p.bfl, math.inf, p)
    return time.perf_counter() - start


def request_costs(samples: int, width: int, height: int, lens: LensPrescription,
                  limits: Limits = LIMITS) -> list[str]:
    """What of a request is beyond ``limits``, one sentence each with its cost.

    Parameters
    ----------
    samples : int
        Lens samples per pixel.
    width, height : int
        The image, px.
    lens : LensPrescription
        The lens; beyond ``limits.surfaces`` one bundle is traced to time it.
    limits : Limits

    Returns
    -------
    list of str
        Empty when the request is usual.
    """
    found = []
    pixels = width * height
    seconds = samples * pixels * SECONDS_PER_PIXEL_SAMPLE
    many = samples > limits.samples and seconds > limits.seconds_beyond_samples
    if many or seconds > 3600.0 * limits.hours:
        usual = (f"the usual is up to {limits.samples:,} samples (--method auto chooses)"
                 if many else
                 f"povlens goes on unasked up to {limits.hours:g} h")
        found.append(
            f"{samples:,} lens samples at {width}x{height} ({samples * pixels:.3g} "
            f"pixel-samples) take about {_duration(seconds)} (at "
            f"{SECONDS_PER_PIXEL_SAMPLE * 1e6:g} us a pixel-sample, measured on POV-Ray's "
            f"woodbox.pov with 2 cores; simpler scenes are faster, radiosity or media "
            f"slower): {usual}")
    if pixels > limits.pixels:
        found.append(
            f"an image of {width}x{height} ({pixels / 1e6:.0f} Mpx) needs about "
            f"{_bytes(pixels * COMPOSITE_BYTES_PER_PIXEL)} of memory to composite; the "
            f"usual is up to 8K UHD (7680x4320)")
    if lens.n_surfaces > limits.surfaces:
        bundle_s = _seconds_per_bundle(lens)
        found.append(
            f"{lens.source} has {lens.n_surfaces:,} surfaces (real lenses have up to about "
            f"40): one bundle of rays takes {bundle_s:.2g} s to trace through it, so "
            f"focusing it alone takes about {_duration(_TRACES_TO_FOCUS * bundle_s)}")
    return found


def check_request_size(samples: int, width: int, height: int, lens: LensPrescription,
                       yes: bool, limits: Limits = LIMITS) -> None:
    """Stop a request beyond ``limits`` unless ``yes``; with ``yes``, warn and go on.

    Raises
    ------
    BigRequestError
        Beyond a limit without ``yes``: the message says what it would cost.
    """
    costs = request_costs(samples, width, height, lens, limits)
    if not costs:
        return
    if not yes:
        raise BigRequestError("; ".join(costs),
                              "add --yes to go on, or ask for less")
    for cost in costs:
        warnings.warn(BigRequestWarning(f"{cost}: going on (--yes)"), stacklevel=2)
