"""Every CSV lensaudit writes (lensaudit.formats.csv_format.write_rows), read
back by Python's csv module: the values as documented, a row per line."""

from __future__ import annotations

import csv
import io
import math

from hypothesis import given
from hypothesis import strategies as st

from lensaudit.formats.csv_format import write_rows

texts = st.text(alphabet=st.sampled_from('ab ,"\r\n;é\t'), max_size=6)
kinds = {
    "float": st.floats(allow_nan=True, allow_infinity=True),
    "text": texts,
    "int": st.integers(-(10**12), 10**12),
    "flag": st.sampled_from([True, False, None]),
    "mixed": st.one_of(st.floats(), texts, st.integers(-5, 5), st.booleans(), st.none()),
}


def expected(value: object) -> str:
    """A value as the module's docstring says it is written, before quoting."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    return str(value)


@st.composite
def tables(draw):
    rows = draw(st.integers(0, 12))
    chosen = draw(st.lists(st.sampled_from(sorted(kinds)), min_size=1, max_size=5))
    header = [f"column {i}, {kind}" for i, kind in enumerate(chosen)]
    columns = [draw(st.lists(kinds[kind], min_size=rows, max_size=rows)) for kind in chosen]
    return header, columns


@given(tables())
def test_rows_read_back_as_the_values_written(table):
    header, columns = table
    stream = io.StringIO()
    write_rows(stream, header, columns)
    text = stream.getvalue()
    assert text.endswith("\n")
    found = list(csv.reader(io.StringIO(text, newline="")))
    rows = [list(map(expected, row)) for row in zip(*columns, strict=True)]
    assert found == [header, *rows]
    for values, written in zip(columns, zip(*found[1:], strict=True), strict=False):
        for value, field in zip(values, written, strict=True):
            if isinstance(value, float) and not math.isnan(value):
                assert float(field) == value and math.copysign(1, float(field)) == math.copysign(
                    1, value
                )


def test_no_rows_is_the_header_alone():
    stream = io.StringIO()
    write_rows(stream, ["a", "b"], [[], []])
    assert stream.getvalue() == "a,b\n"
