"""The solver's scalar kernel (lensaudit.solver.kernel) gives the array code's
metrics bit for bit, wherever it gives any.

The array code (lensaudit.solver.arrays, lensaudit.metrics) is the reference
here; it is itself held to exact rational arithmetic by test_solver_range.py.
"""

from __future__ import annotations

import io
import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from history_blobs import file_versions
from lensaudit import metrics
from lensaudit.columns import METRIC_COLUMNS
from lensaudit.formats import writer
from lensaudit.pipeline import run
from lensaudit.read import read_bytes
from lensaudit.read.records import STATUS_OK, DistortionEntry
from lensaudit.solver import arrays as solver
from lensaudit.solver import kernel as scalar
from test_solver_range import any_double, spread_double

#: Coefficients of the size real lenses have, of either sign.
lens_sized = st.one_of(
    st.just(0.0),
    st.floats(-2.0, 2.0, allow_subnormal=False),
    st.builds(lambda m, e: math.ldexp(m, e), st.floats(-1.0, 1.0), st.integers(-40, 8)),
)


def bits(value: float) -> bytes:
    """The binary64 encoding: equal for the same float, zeros and NaN included."""
    return struct.pack("<d", value)


def assert_same_root(a: float, b: float, c: float) -> None:
    found = scalar.min_positive_root(a, b, c)
    if found is None:
        return
    expected = float(solver.min_positive_root(a, b, c))
    assert bits(found) == bits(expected), f"{(a, b, c)}: {found!r}, array code {expected!r}"


@settings(max_examples=3000, deadline=None)
@given(any_double, any_double, any_double)
def test_root_is_the_array_codes_for_any_doubles(a, b, c):
    assert_same_root(a, b, c)


@settings(max_examples=3000, deadline=None)
@given(spread_double, spread_double, spread_double)
def test_root_is_the_array_codes_across_the_range(a, b, c):
    assert_same_root(a, b, c)


@settings(max_examples=3000, deadline=None)
@given(lens_sized, lens_sized, lens_sized)
def test_root_is_the_array_codes_for_lens_sized_cubics(a, b, c):
    assert_same_root(a, b, c)


def test_every_root_of_a_large_random_sample_is_the_array_codes():
    """Many cubics at once, solved by the array code in one call (its chunked path)."""
    rng = np.random.default_rng(20221)
    size = 60_000
    exponent = rng.integers(-60, 10, (3, size))
    a, b, c = rng.uniform(-1, 1, (3, size)) * np.ldexp(1.0, exponent)
    zero = rng.random((3, size)) < 0.15
    a[zero[0]], b[zero[1]], c[zero[2]] = 0.0, 0.0, 0.0
    expected = solver.min_positive_root(a, b, c)
    answered = 0
    triples = zip(a.tolist(), b.tolist(), c.tolist(), strict=True)
    for args, want in zip(triples, expected.tolist(), strict=True):
        found = scalar.min_positive_root(*args)
        if found is not None:
            answered += 1
            assert bits(found) == bits(want), f"{args}: {found!r}, array code {want!r}"
    # Lens-sized cubics are the fast path's: nearly all are answered.
    assert answered > 0.95 * size


def entry_columns(entries: list[tuple]) -> dict[str, list]:
    names = ("model", "a", "b", "c", "k1", "k2", "crop_factor", "aspect_ratio", "focal")
    return dict(zip(names, map(list, zip(*(e[:-1] for e in entries), strict=True)), strict=True))


def assert_same_metrics(entries: list[tuple]) -> int:
    """entry_metrics of each (model, a, b, c, k1, k2, crop, aspect, focal, circular)
    against metrics.compute of them all; the number answered."""
    columns = entry_columns(entries)
    circular = [e[-1] for e in entries]
    computed = metrics.compute(**columns, audited=[True] * len(entries), circular=circular)
    answered = 0
    for index, entry in enumerate(entries):
        found = scalar.entry_metrics(*entry)
        if found is None:
            continue
        answered += 1
        for name, value in zip(METRIC_COLUMNS, found, strict=True):
            want = getattr(computed, name)[index].item()
            if isinstance(value, float):
                assert bits(value) == bits(want), f"{entry}: {name} {value!r}, array {want!r}"
            else:
                assert value == want, f"{entry}: {name} {value!r}, array code {want!r}"
    return answered


def audited_entries(entries: list[DistortionEntry]) -> list[tuple]:
    """(model, a, b, c, k1, k2, crop, aspect, focal, circular) of each audited entry."""
    return [
        (e.model, e.a, e.b, e.c, e.k1, e.k2, e.crop_factor, e.aspect_ratio, e.focal)
        + (metrics.is_circular_fisheye(e.lens, e.type),)
        for e in entries
        if e.status == STATUS_OK
    ]


def test_every_entry_of_the_bundled_database_is_answered_as_the_array_code_does(bundled_db):
    entries = audited_entries(run(bundled_db).entries)
    # Every one is answered: a scan of the bundled database needs no numpy.
    assert assert_same_metrics(entries) == len(entries) > 5000


def test_entries_across_lensfuns_history_are_answered_as_the_array_code_does(tmp_path):
    found = set()
    for data in file_versions(tmp_path):
        found.update(audited_entries(read_bytes(data, "version.xml").entries()))
    entries = sorted(found, key=repr)
    # Nearly all are answered (the others are left to the array code, as allowed).
    assert assert_same_metrics(entries) > 0.99 * len(entries) > 5000


unused = st.just(math.nan)
model_entries = st.one_of(
    st.tuples(st.just("ptlens"), lens_sized, lens_sized, lens_sized, unused),
    st.tuples(st.just("poly3"), unused, unused, unused, lens_sized),
    st.tuples(st.just("poly5"), unused, unused, unused, lens_sized),
)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.tuples(
            model_entries,
            lens_sized,
            st.floats(0.01, 100),
            st.floats(0.1, 10),
            st.floats(0.1, 2000),
            st.booleans(),
        ),
        min_size=1,
        max_size=20,
    )
)
def test_entry_metrics_are_the_array_codes(drawn):
    entries = []
    for (model, a, b, c, k1), k2, crop, aspect, focal, circular in drawn:
        k2 = k2 if model == "poly5" else math.nan
        entries.append((model, a, b, c, k1, k2, crop, aspect, focal, circular))
    assert_same_metrics(entries)


@settings(max_examples=500, deadline=None)
@given(any_double, any_double, any_double, any_double)
def test_entry_metrics_near_the_ends_of_the_range_are_the_array_codes_or_left_to_it(a, b, c, k1):
    assert_same_metrics(
        [
            ("ptlens", a, b, c, math.nan, math.nan, 1.0, 1.5, 50.0, False),
            ("poly3", math.nan, math.nan, math.nan, k1, math.nan, 1.5, 4 / 3, 20.0, False),
            ("poly5", math.nan, math.nan, math.nan, a, b, 2.0, 1.0, 8.0, True),
        ]
    )


@pytest.mark.parametrize("aspect", [1.5, 4 / 3, 16 / 9, 1.0, 2 / 3, 0.0, -0.0, math.inf, 1e-310])
def test_image_corner_is_the_metrics_one(aspect):
    assert bits(scalar.image_corner(aspect)) == bits(float(metrics.image_corner(aspect)))


def test_half_diagonal_is_hypot_18_12():
    assert scalar.HALF_DIAGONAL_MM == math.sqrt(18.0**2 + 12.0**2) == 21.633307652783937


# -- in the pipeline -------------------------------------------------------------------


def audit_texts(database, monkeypatch, plain: bool) -> tuple[str, str, list, str]:
    """(csv rows, json rows, metric columns as bits, summary) of a fresh audit,
    its metrics from the kernel where it answers, or all from the array code."""
    if not plain:
        monkeypatch.setattr(scalar, "column_metrics", lambda columns, audited: None)
    audit = run(database)
    columns = audit.metric_columns()
    as_bits = [
        [bits(v) if isinstance(v, float) else v for v in columns[name]] for name in METRIC_COLUMNS
    ]
    monkeypatch.undo()
    texts = []
    for name in ("csv", "json"):
        stream = io.StringIO()
        writer(name)(audit, stream)
        texts.append(stream.getvalue())
    return texts[0], texts[1], as_bits, repr(audit.summary.to_dict())


def test_a_scan_of_the_bundled_database_is_the_same_with_the_array_code(bundled_db, monkeypatch):
    plain = audit_texts(bundled_db, monkeypatch, plain=True)
    assert plain == audit_texts(bundled_db, monkeypatch, plain=False)
    assert plain[0].count("\n") > 5000


def test_files_with_an_entry_left_to_the_array_code_are_audited_as_it_does(
    tmp_path, bundled_db, monkeypatch
):
    # 1 - 3 w + 2.25 w^2 = (1 - 1.5 w)^2 touches zero: left to the array code.
    database = tmp_path / "db"
    database.mkdir()
    for name in ("slr-canon.xml", "mil-samyang.xml", "compact-sony.xml"):
        (database / name).write_bytes((bundled_db / name).read_bytes())
    (database / "tangent.xml").write_text(
        "<lensdatabase><lens><maker>M</maker><model>L</model><mount>X</mount><calibration>"
        '<distortion model="poly5" focal="10" k1="-1" k2="0.45"/>'
        '<distortion model="ptlens" focal="20" a="0.01" b="-0.03" c="0.02"/>'
        "</calibration></lens></lensdatabase>"
    )
    assert scalar.entry_metrics("poly5", *[math.nan] * 3, -1.0, 0.45, 1, 1.5, 10, False) is None
    plain = audit_texts(database, monkeypatch, plain=True)
    assert plain == audit_texts(database, monkeypatch, plain=False)
    assert plain[0].count("tangent.xml,1,") == 2


def test_the_solvers_constants_are_numpys_binary64_values():
    # Written as plain Python numbers, so that the kernel needs no numpy.
    from lensaudit.solver import constants

    assert constants.EPS == np.finfo(np.float64).eps
    assert constants.MAX == np.finfo(np.float64).max
    assert constants.SMALLEST_NORMAL == np.finfo(np.float64).tiny
    assert constants.SPLITTER == 2.0**27 + 1
