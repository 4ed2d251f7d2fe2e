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


@dataclasses.dataclass
class _BrentSearch:
    """The state of Brent's bounded search (SciPy's names): the bracket [a, b]; the
    best point so far ``xf`` and the two before it, ``nfc`` and ``fulc``, with their
    values; the step before last ``e`` and the last step ``rat``."""

    a: float
    b: float
    xf: float
    fx: float
    nfc: float
    fnfc: float
    fulc: float
    ffulc: float
    e: float = 0.0
    rat: float = 0.0

    def tolerances(self, xatol: float) -> tuple[float, float, float]:
        """The bracket's midpoint and the tolerances ``tol1``, ``tol2 = 2 tol1``."""
        xm = 0.5 * (self.a + self.b)
        tol1 = _SQRT_EPS * abs(self.xf) + xatol / 3.0
        return xm, tol1, 2.0 * tol1

    def next_point(self, xm: float, tol1: float, tol2: float) -> float:
        """The point to evaluate next: by a parabola through the three best points
        when it is acceptable, else by a golden-section step; at least ``tol1`` away."""
        if not (abs(self.e) > tol1 and self._parabolic_step(xm, tol1, tol2)):
            self.e = self.a - self.xf if self.xf >= xm else self.b - self.xf
            self.rat = _GOLDEN_MEAN * self.e
        return self.xf + (_sign(self.rat) + (self.rat == 0)) * _max(abs(self.rat), tol1)

    def _parabolic_step(self, xm: float, tol1: float, tol2: float) -> bool:
        """Set ``rat`` to the parabolic step if it falls inside the bracket and is less
        than half the step before last; False: a golden-section step is due."""
        xf, fx = self.xf, self.fx
        r = (xf - self.nfc) * (fx - self.ffulc)
        q = (xf - self.fulc) * (fx - self.fnfc)
        p = (xf - self.fulc) * q - (xf - self.nfc) * r
        q = 2.0 * (q - r)
        if q > 0.0:
            p = -p
        q = abs(q)
        r = self.e
        self.e = self.rat
        if not (abs(p) < abs(0.5 * q * r) and p > q * (self.a - xf) and p < q * (self.b - xf)):
            return False
        self.rat = (p + 0.0) / q
        x = xf + self.rat
        if (x - self.a) < tol2 or (self.b - x) < tol2:     # too close to a bound
            self.rat = tol1 * (_sign(xm - xf) + ((xm - xf) == 0))
        return True

    def take(self, x: float, fu: float) -> None:
        """Narrow the bracket with the value ``fu`` at ``x`` and keep the best three."""
        if fu <= self.fx:
            if x >= self.xf:
                self.a = self.xf
            else:
                self.b = self.xf
            self.fulc, self.ffulc = self.nfc, self.fnfc
            self.nfc, self.fnfc = self.xf, self.fx
            self.xf, self.fx = x, fu
            return
        if x < self.xf:
            self.a = x
        else:
            self.b = x
        if fu <= self.fnfc or self.nfc == self.xf:
            self.fulc, self.ffulc = self.nfc, self.fnfc
            self.nfc, self.fnfc = x, fu
        elif fu <= self.ffulc or self.fulc == self.xf or self.fulc == self.nfc:
            self.fulc, self.ffulc = x, fu


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
    x = lo + _GOLDEN_MEAN * (hi - lo)
    fx = func(x)
    num = 1
    fu = math.inf
    s = _BrentSearch(lo, hi, x, fx, x, fx, x, fx)
    xm, tol1, tol2 = s.tolerances(xatol)
    while abs(s.xf - xm) > (tol2 - 0.5 * (s.b - s.a)):
        x = s.next_point(xm, tol1, tol2)
        fu = func(x)
        num += 1
        s.take(x, fu)
        xm, tol1, tol2 = s.tolerances(xatol)
        if num >= maxiter:
            flag = 1
            break
    if math.isnan(s.xf) or math.isnan(s.fx) or math.isnan(fu):
        flag = 2
    return BoundedMinimum(float(s.xf), float(s.fx), num, flag == 0)
