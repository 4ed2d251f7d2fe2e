"""Bounded scalar minimisation without SciPy's import cost.

:func:`bounded_minimum` is SciPy's ``minimize_scalar(method="bounded")`` (Brent's
method on a bounded interval: ``scipy.optimize._optimize._minimize_scalar_bounded``,
after Forsythe, Malcolm & Moler's ``fmin``) step for step, in the same float64
operations, so it returns the same ``x`` bit for bit (``tests/util/test_minimize.py``
compares them).  Importing ``scipy.optimize`` costs ~0.55 s of every command that
focuses a lens (docs/decisions/cli.md, issue 14), for a 60-line loop.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable

__all__ = ["BoundedMinimum", "bounded_minimum"]

_SQRT_EPS = math.sqrt(2.2e-16)
_GOLDEN_MEAN = 0.5 * (3.0 - math.sqrt(5.0))


@dataclasses.dataclass(frozen=True)
class BoundedMinimum:
    """The result of :func:`bounded_minimum`: the point, its value, the function
    evaluations and whether the tolerance was reached (``False``: ``maxiter``
    evaluations were spent, or a value was NaN)."""

    x: float
    fun: float
    nfev: int
    success: bool


def _sign(v: float) -> float:
    """``numpy.sign(v)``: -1, 0 or 1, NaN for NaN."""
    if v != v:
        return v
    return 1.0 if v > 0 else (-1.0 if v < 0 else 0.0)


def _max(a: float, b: float) -> float:
    """``numpy.maximum(a, b)``: NaN if either is."""
    if a != a or b != b:
        return math.nan
    return a if a >= b else b


def bounded_minimum(func: Callable[[float], float], lo: float, hi: float, *,
                    xatol: float = 1e-5, maxiter: int = 500) -> BoundedMinimum:
    """The minimum of ``func`` on [``lo``, ``hi``] by Brent's bounded method.

    Parameters
    ----------
    func : a function of one float returning a float.
    lo, hi : the finite bounds, ``lo <= hi``.
    xatol : absolute tolerance in x.
    maxiter : most evaluations of ``func``.

    Returns
    -------
    BoundedMinimum
        What ``scipy.optimize.minimize_scalar(func, bounds=(lo, hi),
        method="bounded", options={"xatol": xatol, "maxiter": maxiter})`` returns as
        ``x``, ``fun``, ``nfev`` and ``success``.

    Raises
    ------
    ValueError
        For bounds that are not finite or in the wrong order (as SciPy does).
    """
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError("Optimization bounds must be finite scalars.")
    if lo > hi:
        raise ValueError("The lower bound exceeds the upper bound.")
    flag = 0
    a, b = lo, hi
    fulc = a + _GOLDEN_MEAN * (b - a)
    nfc, xf = fulc, fulc
    rat = e = 0.0
    x = xf
    fx = func(x)
    num = 1
    fu = math.inf
    ffulc = fnfc = fx
    xm = 0.5 * (a + b)
    tol1 = _SQRT_EPS * abs(xf) + xatol / 3.0
    tol2 = 2.0 * tol1
    while abs(xf - xm) > (tol2 - 0.5 * (b - a)):
        golden = True
        if abs(e) > tol1:                                 # try a parabolic fit
            golden = False
            r = (xf - nfc) * (fx - ffulc)
            q = (xf - fulc) * (fx - fnfc)
            p = (xf - fulc) * q - (xf - nfc) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            r = e
            e = rat
            if abs(p) < abs(0.5 * q * r) and p > q * (a - xf) and p < q * (b - xf):
                rat = (p + 0.0) / q
                x = xf + rat
                if (x - a) < tol2 or (b - x) < tol2:
                    rat = tol1 * (_sign(xm - xf) + ((xm - xf) == 0))
            else:
                golden = True
        if golden:                                        # a golden-section step
            e = a - xf if xf >= xm else b - xf
            rat = _GOLDEN_MEAN * e
        x = xf + (_sign(rat) + (rat == 0)) * _max(abs(rat), tol1)
        fu = func(x)
        num += 1
        if fu <= fx:
            if x >= xf:
                a = xf
            else:
                b = xf
            fulc, ffulc = nfc, fnfc
            nfc, fnfc = xf, fx
            xf, fx = x, fu
        else:
            if x < xf:
                a = x
            else:
                b = x
            if fu <= fnfc or nfc == xf:
                fulc, ffulc = nfc, fnfc
                nfc, fnfc = x, fu
            elif fu <= ffulc or fulc == xf or fulc == nfc:
                fulc, ffulc = x, fu
        xm = 0.5 * (a + b)
        tol1 = _SQRT_EPS * abs(xf) + xatol / 3.0
        tol2 = 2.0 * tol1
        if num >= maxiter:
            flag = 1
            break
    if math.isnan(xf) or math.isnan(fx) or math.isnan(fu):
        flag = 2
    return BoundedMinimum(float(xf), float(fx), num, flag == 0)
