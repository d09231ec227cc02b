"""`lensaudit check`: fold-between-calibrations, a zoom that folds inside its
image at a focal length between two calibrations, as liblensfun master
interpolates it (issue 24, item 1). The focal lengths the findings name
are held to liblensfun's own interpolation (lf_lens_interpolate_distortion
through ctypes); the real databases to a sampled sweep of every interval."""

from __future__ import annotations

import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from lensaudit import zooms
from lensaudit.check import FOLD_BETWEEN_CALIBRATIONS, FOLD_IN_IMAGE, check
from lensaudit.cli import main
from lensaudit.interpolation import interpolated
from lensaudit.metrics import compute
from lensaudit.pipeline import run
from lensaudit.read.records import MODEL_COEFFICIENTS
from liblensfun_master import interpolate_distortion, lenses, library
from test_zooms_between import ADJACENT, OVERSHOOT

CORNER = math.hypot(1.5, 1)

#: Far from folding anywhere.
GENTLE = [
    (10.0, (0.0, -0.01, 0.0)),
    (11.0, (0.0, -0.008, 0.0)),
    (20.0, (0.0, 0.002, 0.0)),
]
_AT = re.compile(r"folds back inside the image at ([0-9.e+-]+) mm")


def zoom_file(directory: Path, calibrations, name: str = "zoom.xml") -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    rows = "".join(
        f'      <distortion model="ptlens" focal="{f!r}" a="{a!r}" b="{b!r}" c="{c!r}"/>\n'
        for f, (a, b, c) in calibrations
    )
    text = (
        '<lensdatabase version="2">\n  <lens>\n    <maker>Test</maker>\n'
        "    <model>Zoom 10-20mm</model>\n    <mount>Test</mount>\n"
        "    <cropfactor>1.5</cropfactor>\n"
        f"    <calibration>\n{rows}    </calibration>\n  </lens>\n</lensdatabase>\n"
    )
    path = directory / name
    path.write_text(text)
    return path


def between_findings(result):
    return [f for f in result.findings if f.code == FOLD_BETWEEN_CALIBRATIONS]


def liblensfun_r_normalized(path: Path, focal: float) -> float:
    """r_normalized of the model liblensfun master applies at ``focal`` (the
    file's only lens, crop factor 1.5, its own frame)."""
    library()
    (lens,) = lenses(path.read_bytes())
    _, terms = interpolate_distortion(lens, 1.5, focal)
    one = np.ones(1)
    nan = np.full(1, math.nan)
    found = compute(["ptlens"], [terms[0]], [terms[1]], [terms[2]], nan, nan,
                    one, 1.5 * one, one, np.ones(1, dtype=bool))  # fmt: skip
    return float(found.d_max[0]) / CORNER


def test_calibrations_that_clear_the_image_yet_fold_in_between_are_an_error(tmp_path):
    path = zoom_file(tmp_path, OVERSHOOT)
    result = check([path])
    (finding,) = between_findings(result)
    # The spline between 10 and 11 mm also weighs the 20 mm calibration (line 10),
    # which bends it: the finding names it, as a change there shows here.
    related = ((finding.file, 9), (finding.file, 10))
    assert (finding.severity, finding.line, finding.related) == ("error", 8, related)
    assert "whose spline there also weighs 20 mm (line 10)" in finding.message
    assert not [f for f in result.findings if f.code == FOLD_IN_IMAGE]  # neither folds itself
    focal = float(_AT.search(finding.message).group(1))
    assert 10 < focal < 11
    assert liblensfun_r_normalized(path, focal) < 1
    assert liblensfun_r_normalized(path, 10.0) > 1.1 and liblensfun_r_normalized(path, 11.0) > 1.1
    assert result.failed


def test_an_interval_next_to_a_calibration_that_folds_is_that_calibrations_finding(tmp_path):
    path = zoom_file(tmp_path, ADJACENT)
    result = check([path])
    assert {f.line for f in result.findings if f.code == FOLD_IN_IMAGE} == {8, 9}
    assert not between_findings(result)
    # The proof still sees the fold between them, where liblensfun has it.
    audit = run(str(path))
    (calibrations,) = zooms.calibration_sets(audit)
    first = zooms.between(calibrations, [values for _, values in ADJACENT])[0]
    assert first.verdict == zooms.FOLDS and 10 < first.focal < 11
    assert liblensfun_r_normalized(path, first.focal) < 1


def test_a_zoom_far_from_folding_has_no_finding(tmp_path):
    assert not between_findings(check([zoom_file(tmp_path, GENTLE)]))


def test_a_known_fold_between_calibrations_is_known_and_a_new_one_fails(tmp_path):
    before = zoom_file(tmp_path / "before", GENTLE)
    after = zoom_file(tmp_path / "after", OVERSHOOT)
    new = check([after], baseline=before.parent)
    assert [f.known for f in between_findings(new)] == [False]
    known = check([after], baseline=zoom_file(tmp_path / "same", OVERSHOOT).parent)
    assert [f.known for f in between_findings(known)] == [True]
    assert not known.failed


def test_the_cli_names_the_finding_with_file_and_line(tmp_path):
    path = zoom_file(tmp_path, OVERSHOOT)
    outcome = CliRunner().invoke(main, ["check", str(path)])
    assert outcome.exit_code == 1
    assert f"zoom.xml:8: error [{FOLD_BETWEEN_CALIBRATIONS}]" in outcome.output


def sampled_folds(database: Path) -> set[tuple[str, int]]:
    """(file, line of the lower calibration) of every interval between two
    calibrated focal lengths that do not fold themselves where liblensfun's
    interpolated model, sampled at 41 focal lengths (lensaudit.interpolation,
    held to liblensfun in test_interpolation.py), folds inside the image."""
    audit = run(str(database))
    # The sampled rows of each interval, by what r_normalized_at takes besides them.
    sampled: dict[tuple, list[tuple[np.ndarray, tuple[str, int]]]] = {}
    for calibrations in zooms.calibration_sets(audit):
        focals = calibrations.focals
        table = [
            tuple(getattr(audit.entries[i], n) for n in MODEL_COEFFICIENTS[calibrations.model])
            for i in calibrations.indices
        ]
        distinct = sorted(set(focals))
        for low, high in zip(distinct, distinct[1:], strict=False):
            ends = [
                next(i for i in calibrations.indices if audit.entries[i].focal == f)
                for f in (low, high)
            ]
            if any(audit.metrics.r_normalized[i] < 1 for i in ends):
                continue
            at = np.linspace(low, high, 43)[1:-1]
            rows = np.array([interpolated(table, focals, float(f)) for f in at])
            key = (calibrations.model, calibrations.aspect_ratio, calibrations.image_radius)
            place = (Path(audit.entries[ends[0]].file).name, audit.entries[ends[0]].line)
            sampled.setdefault(key, []).append((rows, place))
    found = set()
    for key, intervals in sampled.items():
        # Each row's r_normalized is its own: the rows of many intervals in one call.
        values = zooms.r_normalized_at(key[0], np.concatenate([r for r, _ in intervals]), *key[1:])
        ends = np.cumsum([len(rows) for rows, _ in intervals])[:-1]
        for (_, place), part in zip(intervals, np.split(values, ends), strict=True):
            if np.nanmin(part) < 1:
                found.add(place)
    return found


@pytest.mark.parametrize("database", ["bundled", "master"])
def test_every_sampled_fold_of_a_real_database_is_found(database, bundled_db, request):
    # docs/ci.md quotes the count (none in either).
    source = bundled_db if database == "bundled" else request.getfixturevalue("lensfun_head")
    findings = between_findings(check([source]))
    reported = {(Path(f.file).name, f.line) for f in findings}
    assert sampled_folds(source) == reported
    assert len(findings) == 0


coefficient = st.floats(-0.06, 0.06, allow_nan=False)
magnitude = st.tuples(st.sampled_from([-1.0, 1.0]), st.floats(-300, 300, allow_nan=False)).map(
    lambda pair: pair[0] * 10.0 ** pair[1]
)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(4, 60).map(lambda f: round(f, 1)), min_size=2, max_size=4, unique=True),
    st.lists(st.tuples(magnitude, magnitude, magnitude), min_size=4, max_size=4),
)
def test_clear_is_never_contradicted_over_the_whole_binary64_range(focals, values):
    """Coefficients from 1e-300 to 1e300: no warning, and an interval judged
    clear has no sampled focal length that folds (by the exact solver)."""
    focals = sorted(focals)
    table = values[: len(focals)]
    calibrations = zooms.CalibrationSet(tuple(range(len(focals))), tuple(focals), "ptlens",
                                        1.5, CORNER)  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        verdicts = zooms.between(calibrations, table)
        for interval in verdicts:
            if interval.verdict != zooms.CLEAR:
                continue
            at = np.linspace(interval.low, interval.high, 101)
            rows = np.array([interpolated(table, focals, float(f)) for f in at])
            with np.errstate(all="ignore"):
                values_at = zooms.r_normalized_at("ptlens", rows, 1.5, CORNER)
            assert not np.any(values_at < 1)
