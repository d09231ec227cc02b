"""The constants of the solver, shared by its array code and its scalar kernel.

Plain Python: the scalar kernel (:mod:`lensaudit.solver.kernel`) must not
import numpy, and both must prove their answers with the same margins.
"""

from __future__ import annotations

import math
import struct

#: Unit roundoff of binary64 (numpy.finfo(float).eps), its largest and smallest normal values.
EPS = 2.0**-52
MAX = 1.7976931348623157e308
SMALLEST_NORMAL = 2.0**-1022
SPLITTER = 134217729.0  # 2**27 + 1, for Veltkamp's split
#: Newton steps of the fast path before the certificate is checked.
PLAIN_NEWTON_STEPS = 5
#: Roots whose condition number (sum of |terms| over |x q'(x)|) is below this
#: are accurate to 1e-13 after plain Newton steps; others are polished.
WELL_CONDITIONED = 1e3
#: Scaled coefficients at least this large (or exactly zero) keep every
#: intermediate of the fast path, errors of compensated products included,
#: far from underflow.
SAFE_SCALED = 2.0**-250
#: Half-width, relative, of the interval in which the fast path proves its root.
HALF_WIDTH = 2.0**-44
#: Exponent given to a missing (zero) term, so that it is never the largest.
ABSENT = -(1 << 20)
#: A Cauchy bound of a cubic's roots up to this leaves none beyond the largest
#: double (metrics.roots_in_range, and the kernel's).
ROOTS_IN_RANGE = 2.0**1020
#: Half diagonal of Lensfun's 36 x 24 mm reference sensor, in millimetres.
HALF_DIAGONAL_MM = math.hypot(18.0, 12.0)
#: Bit pattern of MAX: the positive doubles are the patterns 1 to MAX_BITS, in order.
MAX_BITS = 0x7FEFFFFFFFFFFFFF


def float_bits(x: float) -> int:
    """The bit pattern of a double, as an integer (ordered as the positive doubles are)."""
    return struct.unpack("<q", struct.pack("<d", x))[0]


def bits_float(bits: int) -> float:
    """The double of a bit pattern (:func:`float_bits` undone)."""
    return struct.unpack("<d", struct.pack("<q", bits))[0]
