"""Reading one file of 70,000, 140,000 and 280,000 lines: time must grow as the lines do.

Beyond 65,535 lines libxml2 no longer numbers lines, and lensaudit numbers
the elements itself. Two shapes of file: one `<lens>` holding every line
(one piece of the stream, as large as the file), and lenses of a dozen lines
each (the shape of a real database). Each is read by `read_bytes` in this
process, in turns, medians; "x 70k" is the time over that of the file of
70,000 lines of the same shape (ideally the lines' ratio: 2 and 4).
"""

from __future__ import annotations

import statistics
import time

TITLE = "Reading one file of 70k to 280k lines (read_bytes, in-process)"

LINES = (70_000, 140_000, 280_000)

_LENS = """\
    <lens>
        <maker>Test</maker>
        <model>Test 10mm</model>
        <mount>Test Mount</mount>
        <cropfactor>1</cropfactor>
        <calibration>
{rows}
        </calibration>
    </lens>
"""
_ROW = '            <distortion model="ptlens" focal="{:.3f}" a="0.01" b="-0.02" c="0.03"/>'


def build(lines: int, one_piece: bool) -> bytes:
    """A database of about ``lines`` lines: one lens, or lenses of 12 lines."""
    if one_piece:
        rows = "\n".join(_ROW.format(10 + n / 1000) for n in range(lines - 10))
        body = _LENS.format(rows=rows)
    else:
        lens = _LENS.format(rows="\n".join(_ROW.format(10 + n) for n in range(3)))
        body = lens * (lines // lens.count("\n"))
    return f'<lensdatabase version="2">\n{body}</lensdatabase>\n'.encode()


def run(quick: bool) -> list[dict]:
    from lensaudit.read import read_bytes

    repeats = 1 if quick else 3
    rows = []
    for one_piece, shape in ((True, "one <lens>"), (False, "lenses of 12 lines")):
        files = {lines: build(lines, one_piece) for lines in LINES}
        samples: dict[int, list[float]] = {lines: [] for lines in LINES}
        for _ in range(repeats):
            for lines, data in files.items():
                start = time.perf_counter()
                tables = read_bytes(data, "a.xml")
                samples[lines].append(time.perf_counter() - start)
                assert tables.status == "ok"
        first = statistics.median(samples[LINES[0]])
        for lines, data in files.items():
            seconds = statistics.median(samples[lines])
            counted = data.count(b"\n")
            rows.append(
                {
                    "shape": shape,
                    "lines": f"{counted:,}",
                    "median s": seconds,
                    "x 70k": seconds / first,
                    "us/line": 1e6 * seconds / counted,
                }
            )
    return rows
