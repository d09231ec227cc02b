"""The smallest positive root at which 1 + a w + b w^2 + c w^3 changes sign.

Every distortion model here reduces r_max to that root (see
:mod:`lensaudit.normalizer`). The paper's Algorithm 1 computes it with the
cubic formula alone; in floating point that loses the root when c is tiny
next to a and b, when roots cluster, and it counts a double (tangent) root,
where the polynomial touches zero without crossing, as a fold.

For p(w) = 1 + a w + b w^2 + c w^3 with any finite binary64 coefficients,
:func:`min_positive_root` takes one of three paths per element, each
answer proven before it is returned:

1. Fast path. Scale w by a power of two 2^t chosen per element, each
   coefficient by its own power (a 2^t, b 2^2t, c 2^3t: exact, and no scale
   factor that could overflow), so that the coefficients are at most 1 in
   size. Work with the reversed, monic cubic q(x) = x^3 + A x^2 + B x + C,
   x = 2^t / w: the first sign change of p is the largest x > 0 below which q
   is negative. Bracket it between the critical points of q, decide the sign
   at the local minimum with compensated (error-free) arithmetic or the
   exact discriminant, and polish with Newton steps. The answer is accepted
   only where no scaled coefficient came near underflow and a certificate
   holds: q < 0 at x (1 - 2^-44), while at x (1 + 2^-44) q and q' are
   positive and q' cannot vanish further out (q'' > 0 there, or q' has no
   real root), each sign beyond its rounding-error bound. Then q is positive
   and increasing beyond, and the sign change is within 2^-44 of x.
2. Everything else is first decided exactly. Since p(0) = 1, a sign change on
   (0, inf) exists exactly when c < 0; or when c > 0, some coefficient is
   negative and the discriminant is positive (three real roots, so Descartes'
   rule of signs counts the positive ones exactly); or for lower degrees, by
   the same reasoning on the quadratic and linear cases. With a repeated
   root (zero discriminant), p crosses exactly when c < 0. The discriminant's sign is
   computed from the coefficients' mantissas and exponents, so that no term
   overflows or underflows, with a rounding-error bound; where the bound
   cannot tell, it is computed exactly in integers. The same signs tell which
   root is wanted (the first of one, two or three positive roots), and so
   give an exact test "is the root at most X" from the signs of p, p' and
   p'' at X, each evaluated at X's own scale (scaled so that the largest
   term is about 1) with a rounding-error bound. Estimates of the root (the
   fast path with its negligible coefficients dropped, and the roots of
   a + b w + c w^2, which p approaches for w far beyond the fast path's
   scale), polished by Newton's method at their own scale, are accepted
   where the test proves the root within 64 doubles of them; otherwise
   bisection over the bit patterns of positive doubles with the test
   brackets the root between two adjacent doubles.
3. Where a sign in step 2 is too close to call even with compensated
   arithmetic (tangencies and near-triple roots), or the discriminant is
   exactly zero, the same test runs in exact integer arithmetic on the
   binary64 inputs, and the result is rounded correctly.

Accuracy: the finite/infinite decision is exact for all finite binary64
inputs; the relative error is at most 2^-43 (about 1.1e-13) wherever the root
is a normal double (usually a unit or so in the last place). ``inf`` means
no sign change up to the largest double. A subnormal root comes back finite
and positive.

The package: :mod:`~lensaudit.solver.arrays` is the solver over numpy
arrays (all three paths); :mod:`~lensaudit.solver.kernel`, its private
kernel, runs the fast path and the metrics one entry at a time in plain
Python, bit for bit as the array code does (tests/test_scalar.py), and
leaves every other entry to it, so that a scan need not import numpy;
:mod:`~lensaudit.solver.constants` holds the margins both prove with.
"""

from __future__ import annotations

# typing only for type checkers: importing the kernel must stay light.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any

__all__ = [
    "PATHS",
    "min_positive_root",
    "min_positive_root_paper",
    "min_positive_root_paper_vectorized",
    "min_positive_root_paths",
]


def __getattr__(name: str) -> Any:
    # The array code, imported when first used: it imports numpy.
    if name in __all__ or name.startswith("_"):
        from . import arrays  # numpy: the kernel answers without it

        try:
            return getattr(arrays, name)
        except AttributeError:
            pass
    raise AttributeError(f"module 'lensaudit.solver' has no attribute {name!r}")
