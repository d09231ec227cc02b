"""Reference answers for the solver, computed independently in exact arithmetic.

The binary64 inputs are taken exactly as rationals. Roots of odd multiplicity
are separated from the others exactly (square-free decomposition with
rationals), their number on (0, inf) is counted exactly (Sturm's theorem), and
only then located numerically with mpmath at 60 significant digits, or, over
the whole binary64 range, by bisection in exact rationals
(:func:`odd_root_bracket`).
"""

from __future__ import annotations

import math
from fractions import Fraction

import mpmath

mpmath.mp.dps = 60
INF = mpmath.inf

Poly = list[Fraction]  # coefficients, constant term first


def _trim(p: Poly) -> Poly:
    p = list(p)
    while p and p[-1] == 0:
        p.pop()
    return p


def _derivative(p: Poly) -> Poly:
    return _trim([k * p[k] for k in range(1, len(p))])


def _divmod(n: Poly, d: Poly) -> tuple[Poly, Poly]:
    n, d = _trim(n), _trim(d)
    quotient = [Fraction(0)] * max(len(n) - len(d) + 1, 0)
    while len(n) >= len(d) and n:
        factor = n[-1] / d[-1]
        shift = len(n) - len(d)
        quotient[shift] = factor
        n = _trim(
            [
                n[i] - factor * (d[i - shift] if 0 <= i - shift < len(d) else 0)
                for i in range(len(n))
            ]
        )
    return quotient, n


def _gcd(p: Poly, q: Poly) -> Poly:
    p, q = _trim(p), _trim(q)
    while q:
        p, q = q, _divmod(p, q)[1]
    return [x / p[-1] for x in p]


def _odd_multiplicity_part(p: Poly) -> Poly:
    """The product of the distinct roots of odd multiplicity (degree <= 3)."""
    g = _gcd(p, _derivative(p))
    if len(g) <= 1:
        return p  # square-free
    if len(g) == 2:
        # p = (x - r)^2 h with h linear, or p = (x - r)^2: the double root is even.
        h, remainder = _divmod(p, _mul(g, g))
        assert not remainder
        return h
    return _divmod(g, _gcd(g, _derivative(g)))[0]  # p = (x - r)^3: the root r, once


def _mul(p: Poly, q: Poly) -> Poly:
    out = [Fraction(0)] * (len(p) + len(q) - 1)
    for i, x in enumerate(p):
        for j, y in enumerate(q):
            out[i + j] += x * y
    return out


def _sturm_sequence(p: Poly) -> list[Poly]:
    sequence = [p, _derivative(p)]
    while len(sequence[-1]) > 1:
        remainder = _divmod(sequence[-2], sequence[-1])[1]
        if not remainder:
            break
        sequence.append([-x for x in remainder])
    return sequence


def _sign_changes(values: list[Fraction | int]) -> int:
    signs = [v > 0 for v in values if v != 0]
    return sum(1 for s, t in zip(signs, signs[1:], strict=False) if s != t)


def _positive_root_count(p: Poly) -> int:
    """Distinct real roots of square-free p in (0, inf), by Sturm's theorem."""
    sequence = _sturm_sequence(p)
    at_zero = [s[0] if s else 0 for s in sequence]
    at_infinity = [s[-1] if s else 0 for s in sequence]
    return _sign_changes(at_zero) - _sign_changes(at_infinity)


def exact_roots(a: float, b: float, c: float) -> tuple[mpmath.mpf, list[mpmath.mpc]]:
    """(smallest positive root of odd multiplicity or inf, all roots with multiplicity).

    Of p(w) = 1 + a w + b w^2 + c w^3 with the binary64 values taken exactly.
    """
    p = _trim([Fraction(1), Fraction(a), Fraction(b), Fraction(c)])
    if len(p) <= 1:
        return INF, []
    g = _gcd(p, _derivative(p))
    distinct = _divmod(p, g)[0]  # square-free: every root once
    all_roots = _roots(distinct)
    if len(g) == 2:  # one double root, rational
        all_roots.append(mpmath.mpf(-g[0].numerator) / g[0].denominator)
    elif len(g) == 3:  # a triple root: twice more
        all_roots += all_roots[:1] * 2
    odd = _odd_multiplicity_part(p)
    count = _positive_root_count(odd) if len(odd) > 1 else 0
    if count == 0:
        return INF, all_roots
    candidates = _roots(odd)
    # Exactly `count` roots are real and positive: the ones nearest the positive axis.
    candidates.sort(key=lambda z: (abs(mpmath.im(z)) / (abs(z) + 1e-300), -mpmath.re(z)))
    real_positive = sorted(mpmath.re(z) for z in candidates[:count])
    return real_positive[0], all_roots


def _roots(p: Poly) -> list[mpmath.mpc]:
    """Roots of a square-free polynomial, to the working precision.

    The extra precision grows with the spread of the coefficients' exponents,
    so that roots of very different sizes all come out accurate.
    """
    if len(p) <= 1:
        return []
    exponents = [x.numerator.bit_length() - x.denominator.bit_length() for x in p if x]
    extra = 120 + 3 * (max(exponents) - min(exponents))
    coefficients = [mpmath.mpf(x.numerator) / x.denominator for x in reversed(p)]
    steps = 100
    for _ in range(4):
        try:
            return list(mpmath.polyroots(coefficients, maxsteps=steps, extraprec=extra))
        except mpmath.libmp.libhyper.NoConvergence:
            steps *= 4
            extra *= 2
    raise ArithmeticError(f"mpmath found no roots for {p}")


def exact_min_positive_root(a: float, b: float, c: float) -> mpmath.mpf:
    """Smallest w > 0 where 1 + a w + b w^2 + c w^3 changes sign (mpmath inf if none)."""
    return exact_roots(a, b, c)[0]


def separation(a: float, b: float, c: float) -> mpmath.mpf:
    """Relative distance from the reference root to the nearest other root (complex too).

    A multiple root counts as at distance 0 from itself. inf when the root is
    infinite or the polynomial has no other root.
    """
    return reference(a, b, c)[1]


def reference(a: float, b: float, c: float) -> tuple[mpmath.mpf, mpmath.mpf]:
    """(exact_min_positive_root, separation) in one computation."""
    root, all_roots = exact_roots(a, b, c)
    if root == INF:
        return INF, INF
    distances = sorted(abs(z - root) for z in all_roots)
    others = distances[1:]  # the nearest one is the root itself
    if not others:
        return root, INF
    return root, others[0] / abs(root)


# -- the whole binary64 range ------------------------------------------------------------
#
# mpmath's polyroots struggles when the roots differ by hundreds of orders of
# magnitude, so over the whole range the root is isolated in exact arithmetic
# alone: Sturm's theorem on the odd-multiplicity part counts roots in (0, X] for
# rational X, and bisection over powers of two, then within one binade, narrows
# the smallest one down.

#: The largest binary64 number, exactly.
MAX_FLOAT = Fraction(1.7976931348623157e308)


def _integer_polynomial(p: Poly) -> list[int]:
    """p times the (positive) common denominator of its coefficients."""
    denominator = 1
    for x in p:
        denominator = denominator * x.denominator // math.gcd(denominator, x.denominator)
    return [int(x * denominator) for x in p]


def _integer_sign(p: list[int], x: Fraction) -> int:
    """Sign of p(x), by Horner's rule on p(n/d) d^deg in integers."""
    n, d = x.numerator, x.denominator
    value, power = 0, 1
    for coefficient in reversed(p):
        value = value * n + coefficient * power
        power *= d
    # value = d^deg p(n/d), and d > 0.
    return (value > 0) - (value < 0)


def _variations(sequence: list[list[int]], x: Fraction | None) -> int:
    """Sign variations of the Sturm sequence at x (None: at +infinity)."""
    if x is None:
        values = [s[-1] for s in sequence if s]
    else:
        values = [_integer_sign(s, x) for s in sequence]
    return _sign_changes(values)


def odd_root_bracket(
    a: float, b: float, c: float, bits: int = 90
) -> tuple[Fraction, Fraction] | None:
    """(lo, hi] holding the smallest w > 0 where 1 + a w + b w^2 + c w^3 changes sign.

    Exact rationals with hi - lo <= 2^-bits lo; None where there is no such w.
    """
    p = _trim([Fraction(1), Fraction(a), Fraction(b), Fraction(c)])
    odd = _odd_multiplicity_part(p) if len(p) > 1 else [Fraction(1)]
    if len(odd) <= 1:
        return None
    sequence = [_integer_polynomial(s) for s in _sturm_sequence(odd)]
    at_zero = _variations(sequence, Fraction(0))
    if at_zero - _variations(sequence, None) == 0:
        return None

    def any_root_up_to(x: Fraction) -> bool:
        return at_zero - _variations(sequence, x) > 0

    # Every root exceeds 2^-1100 (1/(3 max(|a|, |b|^1/2, |c|^1/3)) > 2^-1027) and
    # lies below 2^2200 (|b/c| < 2^2098, the Cauchy bound).
    low, high = -1100, 2200
    while high - low > 1:
        middle = (low + high) // 2
        if any_root_up_to(Fraction(2) ** middle):
            high = middle
        else:
            low = middle
    lo, hi = Fraction(2) ** low, Fraction(2) ** high
    for _ in range(bits):
        middle = (lo + hi) / 2
        if any_root_up_to(middle):
            hi = middle
        else:
            lo = middle
    return lo, hi


def exceeds_max_float(a: float, b: float, c: float) -> bool:
    """True where there is no sign change of 1 + a w + b w^2 + c w^3 in (0, MAX_FLOAT]."""
    p = _trim([Fraction(1), Fraction(a), Fraction(b), Fraction(c)])
    odd = _odd_multiplicity_part(p) if len(p) > 1 else [Fraction(1)]
    if len(odd) <= 1:
        return True
    sequence = [_integer_polynomial(s) for s in _sturm_sequence(odd)]
    return _variations(sequence, Fraction(0)) == _variations(sequence, MAX_FLOAT)
