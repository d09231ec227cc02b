"""Damage for cache files: bytes flipped as hypothesis draws them."""

from __future__ import annotations

from hypothesis import strategies as st

#: One to four flips: a position (taken modulo the size of what is flipped)
#: and a non-zero XOR mask.
FLIPS = st.lists(st.tuples(st.integers(0, 1 << 24), st.integers(1, 255)), min_size=1, max_size=4)


def flipped(data: bytes, flips: list[tuple[int, int]]) -> bytes:
    """``data`` with ``flips`` applied (two flips of one byte may cancel out)."""
    damaged = bytearray(data)
    for position, mask in flips:
        damaged[position % len(damaged)] ^= mask
    return bytes(damaged)
