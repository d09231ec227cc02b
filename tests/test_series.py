"""`lensaudit check`: focal-series-outlier, a distortion entry that breaks the
smooth course of its lens's calibration over focal length (a warning)."""

from __future__ import annotations

import importlib.util
import math
import random
import subprocess
import sys
import warnings
from fractions import Fraction
from pathlib import Path

import pytest

from conftest import git_commit
from lensaudit.check import check
from lensaudit.check.rules.focal_series_outlier import displacement

ROOT = Path(__file__).resolve().parents[1]
CODE = "focal-series-outlier"
#: k1 of a smooth poly3 series: -0.02 at 18 mm, rising by 0.01 per unit of ln(focal).
FOCALS = (18, 24, 35, 50, 70, 105)


def smooth_k1(focal: float) -> float:
    return -0.02 + 0.01 * math.log(focal / 18)


def poly3(focal: float, k1: float) -> str:
    return f'<distortion model="poly3" focal="{focal:g}" k1="{k1:.6g}"/>'


def database(directory: Path, *lenses: list[str], crop: str = "1.5") -> Path:
    """A database of lenses, each given as its <distortion> lines; line numbers:
    the first lens's first <distortion> is on line 7, one per line after it."""
    directory.mkdir(parents=True, exist_ok=True)
    parts = ['<lensdatabase version="2">']
    for number, lines in enumerate(lenses):
        parts += [
            "  <lens>",
            f"    <maker>Test</maker><model>Zoom {number}</model>",
            "    <mount>Test</mount>",
            f"    <cropfactor>{crop}</cropfactor>",
            "    <calibration>",
            *(f"      {line}" for line in lines),
            "    </calibration>",
            "  </lens>",
        ]
    parts.append("</lensdatabase>")
    (directory / "db.xml").write_text("\n".join(parts) + "\n")
    return directory


def outliers(result) -> list[tuple[str, int, float]]:
    return [(f.entry_key[1], f.line, f.entry_key[4]) for f in result.findings if f.code == CODE]


def series(spike_at: float | None = None, spike: float = 0.05, focals=FOCALS) -> list[str]:
    return [poly3(f, smooth_k1(f) + (spike if f == spike_at else 0)) for f in focals]


def test_a_smooth_series_has_no_outlier(tmp_path):
    assert outliers(check(database(tmp_path, series()))) == []


def test_one_spike_in_a_smooth_series_is_flagged_and_its_neighbours_are_not(tmp_path):
    # The spike moves the corner (R = hypot(1.5, 1)) by R (R^2 - 1) 0.05 = 0.20
    # Hugin units; the rest of the series spans R (R^2 - 1) 0.01 ln(105/18) = 0.07.
    result = check(database(tmp_path, series(spike_at=50)))
    assert outliers(result) == [("Zoom 0", 10, 50)]
    finding = next(f for f in result.findings if f.code == CODE)
    assert finding.severity == "warning" and not result.failed
    assert "35 mm and 70 mm" in finding.message


def test_a_spike_at_the_long_end_is_flagged(tmp_path):
    assert outliers(check(database(tmp_path, series(spike_at=105)))) == [("Zoom 0", 12, 105)]


def test_the_short_end_may_turn_but_not_leap(tmp_path):
    # A wide end that turns against the trend by 0.05 in k1 (0.2 at the corner,
    # under ten times the spread 0.07 of the rest) is how zooms are ...
    assert outliers(check(database(tmp_path, series(spike_at=18)))) == []
    # ... one that leaps by 0.3 in k1 (1.2 at the corner) is not.
    result = check(database(tmp_path, series(spike_at=18, spike=0.3)))
    assert outliers(result) == [("Zoom 0", 7, 18)]


@pytest.mark.parametrize("count", [2, 3])
def test_a_series_of_two_or_three_is_never_judged(tmp_path, count):
    lines = series(spike_at=FOCALS[count - 1], spike=0.5, focals=FOCALS[:count])
    assert outliers(check(database(tmp_path, lines))) == []


def test_a_series_is_one_lens_crop_factor_and_model(tmp_path):
    # Two lenses of three entries each, and one lens whose four entries are
    # two of poly3 and two of ptlens: no series of four, nothing judged.
    mixed = series(focals=(18, 24)) + [
        '<distortion model="ptlens" focal="35" a="0" b="0.3" c="0"/>',
        '<distortion model="ptlens" focal="50" a="0" b="0" c="0"/>',
    ]
    three = series(spike_at=24, spike=0.5, focals=(18, 24, 35))
    assert outliers(check(database(tmp_path, three, three, mixed))) == []


def test_a_reordered_file_gives_the_same_findings(tmp_path):
    lines = series(spike_at=35)
    ordered = outliers(check(database(tmp_path / "a", lines, series(spike_at=70))))
    shuffled = lines[:]
    random.Random(4).shuffle(shuffled)
    assert shuffled != lines
    reordered = outliers(check(database(tmp_path / "b", shuffled, series(spike_at=70))))
    assert [(lens, focal) for lens, _, focal in reordered] == [
        (lens, focal) for lens, _, focal in ordered
    ]
    assert [(lens, focal) for lens, _, focal in ordered] == [("Zoom 0", 35), ("Zoom 1", 70)]


def test_a_duplicate_focal_length_is_judged_once(tmp_path):
    lines = series(spike_at=50)
    lines.insert(4, lines[3])  # 50 mm twice, the same entry
    result = check(database(tmp_path, lines))
    assert outliers(result) == [("Zoom 0", 10, 50)]


def test_a_known_outlier_stays_known_when_its_neighbour_changes(tmp_path):
    before = database(tmp_path / "before", series(spike_at=50))
    changed = series(spike_at=50)
    changed[4] = poly3(70, smooth_k1(70) + 0.001)
    result = check(database(tmp_path / "after", changed), baseline=before)
    assert [(f.code, f.known) for f in result.findings if f.code == CODE] == [(CODE, True)]


def test_an_overflowing_series_is_not_judged_and_does_not_warn(tmp_path, recwarn):
    lines = series(spike_at=50)
    lines[0] = poly3(18, 1e308)  # its displacement at the corner overflows
    result = check(database(tmp_path, lines))
    assert outliers(result) == []
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]


HUGE = {
    # One entry whose displacement is infinite: a series of one, not judged.
    "alone": (['<distortion model="poly3" focal="10" k1="1e308"/>'], []),
    # A finite displacement near the largest double in a smooth series: the
    # spread of the others around it times its factor overflows. It is the
    # outlier; its neighbours, whose spreads hold it, are not.
    "in the middle": (
        [
            f'<distortion model="ptlens" focal="{focal}" a="0.01" b="-0.02" c="{c}"/>'
            for focal, c in ((10, 0.01), (12, 0.01), (14, 1e308), (16, 0.01), (18, 0.01))
        ],
        [("Zoom 0", 9, 14.0)],
    ),
}


@pytest.mark.parametrize(("lines", "expected"), HUGE.values(), ids=HUGE.keys())
def test_a_series_with_a_huge_value_gives_no_runtime_warning(tmp_path, lines, expected):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = check(database(tmp_path, lines))
    assert outliers(result) == expected


@pytest.mark.parametrize(
    ("model", "coefficients"),
    [
        ("ptlens", (0.00704, 0.002809, 0.0, 0.0, 0.0)),
        ("ptlens", (-0.0123, 0.0456, -0.0789, 0.0, 0.0)),
        ("poly3", (0.0, 0.0, 0.0, -0.0317, 0.0)),
        ("poly5", (0.0, 0.0, 0.0, -0.12, 0.034)),
    ],
)
def test_the_displacement_is_the_model_s_distorted_radius_minus_the_radius(model, coefficients):
    a, b, c, k1, k2 = map(Fraction, coefficients)
    for radius in (0.5, 1.0, 1.25, 1.8028):
        r = Fraction(radius)
        distorted = {
            "ptlens": r * (a * r**3 + b * r**2 + c * r + 1 - a - b - c),
            "poly3": r * (1 - k1 + k1 * r**2),
            "poly5": r * (1 + k1 * r**2 + k2 * r**4),
        }[model]
        expected = float(distorted - r)
        got = float(displacement(model, *coefficients, radius))
        assert got == pytest.approx(expected, rel=1e-12, abs=1e-15)


# -- real data ---------------------------------------------------------------------


def test_lensfun_issue_1024_is_flagged(bundled_db, lensfun_head):
    # Canon EF 35-80mm f/4-5.6 III at 80 mm: a = 0.00704, where the rest of
    # the series has a = 0 or about 0.003 (Lensfun issue #1024).
    for directory, line in ((bundled_db, 2126), (lensfun_head, 2268)):
        found = [
            (Path(f.file).name, f.line, f.entry_key[4])
            for f in check(directory).findings
            if f.code == CODE and f.entry_key[1] == "Canon EF 35-80mm f/4-5.6 III"
        ]
        assert found == [("slr-canon.xml", line, 80.0)]


def independent_outliers(directory: Path) -> set[tuple[str, str, float]]:
    """(file, lens, focal) of the outliers as the module's docstring defines
    them, worked out from the XML with lxml and plain floats."""
    from lxml import etree

    def number(text: str | None, default: float) -> float:
        if text is None:
            return default
        if ":" in text:
            width, height = text.split(":")
            return float(width) / float(height)
        return float(text)

    def profile(element, aspect: float) -> list[float]:
        get = {k: float(element.get(k, "0")) for k in ("a", "b", "c", "k1", "k2")}
        corner = math.hypot(aspect, 1)
        values = []
        for t in (0.5, 0.75, 1.0):
            r = t * corner
            model = element.get("model")
            if model == "ptlens":
                a, b, c = get["a"], get["b"], get["c"]
                values.append(r * (a * r**3 + b * r**2 + c * r + 1 - a - b - c) - r)
            elif model == "poly3":
                values.append(r * (1 - get["k1"] + get["k1"] * r**2) - r)
            else:
                values.append(r * (1 + get["k1"] * r**2 + get["k2"] * r**4) - r)
        return values

    found = set()
    for path in sorted(directory.glob("*.xml")):
        for lens in etree.parse(str(path)).getroot().iter("lens"):
            model_name = next(m.text for m in lens.findall("model") if m.get("lang") is None)
            crop = lens.findtext("cropfactor")
            aspect = lens.findtext("aspect-ratio")
            groups: dict[tuple, dict[float, list[float]]] = {}
            for calibration in lens.findall("calibration"):
                crop_here = calibration.get("cropfactor", crop)
                aspect_here = number(calibration.get("aspect-ratio", aspect), 1.5)
                for element in calibration.findall("distortion"):
                    key = (crop_here, aspect_here, element.get("model"))
                    focal = float(element.get("focal"))
                    groups.setdefault(key, {}).setdefault(focal, profile(element, aspect_here))
            for by_focal in groups.values():
                focals = sorted(by_focal)
                if len(focals) < 4:
                    continue
                ys = [by_focal[f] for f in focals]
                xs = [math.log(f) for f in focals]
                n = len(focals)
                for i in range(n):
                    rest = [y for j, y in enumerate(ys) if j != i]
                    spread = max(
                        max(y[k] for y in rest) - min(y[k] for y in rest) for k in range(3)
                    )
                    deviations = []
                    for k in range(3):
                        if i == 0:
                            deviations.append(abs(ys[0][k] - ys[1][k]))
                            continue
                        near, far = (i - 1, i + 1) if i < n - 1 else (n - 2, n - 3)
                        slope = (ys[far][k] - ys[near][k]) / (xs[far] - xs[near])
                        line = ys[near][k] + slope * (xs[i] - xs[near])
                        if i < n - 1:
                            deviations.append(abs(ys[i][k] - line))
                        else:
                            low, high = sorted((ys[near][k], line))
                            deviations.append(max(low - ys[i][k], ys[i][k] - high, 0))
                    deviation = max(deviations)
                    factor = 10 if i == 0 else 1.5
                    if deviation >= 0.01 and deviation >= factor * spread:
                        found.add((path.name, model_name, focals[i]))
    return found


@pytest.mark.parametrize("which", ["bundled", "master"])
def test_the_outliers_on_real_data_are_the_independent_ones(which, bundled_db, lensfun_head):
    directory = bundled_db if which == "bundled" else lensfun_head
    expected = independent_outliers(directory)
    found = {
        (Path(f.file).name, f.entry_key[1], f.entry_key[4])
        for f in check(directory).findings
        if f.code == CODE
    }
    assert found == expected
    assert len(found) == 5  # docs/ci.md quotes the count and names them


# -- scripts/series_history.py on a hand-made history ----------------------------


def load_script(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(name, module)
    spec.loader.exec_module(module)
    return module


def commit_database(repository: Path, date: str, *lenses: list[str]) -> None:
    """Commit data/db/db.xml holding ``lenses`` (see :func:`database`) at ``date``."""
    database(repository / "data" / "db", *lenses)
    text = (repository / "data" / "db" / "db.xml").read_text()
    git_commit(repository, {"data/db/db.xml": text}, date, date)


@pytest.fixture
def series_history_repository(tmp_path) -> Path:
    repository = tmp_path / "lensfun"
    repository.mkdir()
    subprocess.run(["git", "-C", str(repository), "init", "-q"], check=True)
    spiked_a, spiked_d = series(spike_at=50), series(spike_at=70)
    smooth, three = series(), series(focals=(18, 24, 35))
    # R: Zoom 0 and Zoom 3 have an outlier each (at 50 and 70 mm).
    commit_database(repository, "2021-05-30T12:00:00+00:00", spiked_a, smooth, three, spiked_d)
    # Corrects Zoom 0 at 50 mm: (a) one of two corrected, (b) a correction, flagged.
    commit_database(repository, "2021-06-10T12:00:00+00:00", smooth, smooth, three, spiked_d)
    # Changes two entries of Zoom 1: a correction, not flagged.
    zoom1 = smooth[:]
    zoom1[1], zoom1[2] = poly3(24, 0.001), poly3(35, 0.002)
    commit_database(repository, "2021-07-01T12:00:00+00:00", smooth, zoom1, three, spiked_d)
    # The middle of a series of three: a correction, not flagged (never judged).
    three_changed = [three[0], poly3(24, -0.01), three[2]]
    commit_database(repository, "2021-08-01T12:00:00+00:00", smooth, zoom1, three_changed, spiked_d)
    # Three entries of one series at once, and one added to another: not corrections.
    zoom0 = [poly3(f, smooth_k1(f) + 0.001) if f < 40 else poly3(f, smooth_k1(f)) for f in FOCALS]
    more = [*three_changed, poly3(50, 0.0)]
    commit_database(repository, "2021-09-01T12:00:00+00:00", zoom0, zoom1, more, spiked_d)
    return repository


def test_series_history_counts_a_hand_made_history(series_history_repository):
    series_history = load_script("series_history")
    found = series_history.measure(series_history_repository, "2021-05-30")
    # (a) Zoom 0 at 50 mm and Zoom 3 at 70 mm are flagged at R; only the first is corrected.
    flagged = sorted((e.identity[1], e.identity[3][0], c is not None) for e, c in found.flagged)
    assert flagged == [("zoom0", 50.0, True), ("zoom3", 70.0, False)]
    # (b) three series corrections (Zoom 0, Zoom 1, Zoom 2), one flagged at its parent.
    assert [(lens, size, hit) for _, lens, size, hit in found.corrections] == [
        ("zoom0", 6, True),
        ("zoom1", 6, False),
        ("zoom2", 3, False),
    ]
    assert "(a) flagged at R: 2, corrected later: 1" in series_history.table(found)


def test_the_revision_is_the_last_commit_of_that_day(series_history_repository):
    series_history = load_script("series_history")
    first = subprocess.run(
        ["git", "-C", str(series_history_repository), "rev-list", "--max-parents=0", "HEAD"],
        capture_output=True, text=True, check=True,
    ).stdout.strip()  # fmt: skip
    assert series_history.revision_at(series_history_repository, "2021-05-30") == first
    assert series_history.revision_at(series_history_repository, "2021-06-09") == first
