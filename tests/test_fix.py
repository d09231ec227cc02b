"""`lensaudit fix`: refitted models checked in exact arithmetic, patches byte by byte.

References are independent of lensaudit.fix: the models' D(r) are written
out here from Lensfun's formulas with the coefficients as exact rationals
(sympy), "increasing up to the target" is the absence of real roots of D'
in (0, target], the maximum change of D is found from the exact critical
points, and the RMS change over the image by scipy's adaptive quadrature.
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
import shutil
import warnings
from fractions import Fraction
from pathlib import Path

import pytest
import sympy
from click.testing import CliRunner
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from conftest import lens_xml
from lensaudit import fix, read
from lensaudit.cli import main
from lensaudit.metrics import compute
from lensaudit.pipeline import run
from lensaudit.read.records import STATUS_OK
from lensaudit.xmlpatch import PatchError, write

R = sympy.Symbol("r", positive=True)
TOLERANCE = 50.0
#: The margin fix reaches by default: check's, below which it warns (fold-near-image).
MARGIN = sympy.Rational(11, 10)


def px_per_unit(aspect_ratio: float) -> float:
    """Pixels of a 6000 x 4000 frame per Hugin unit of a model calibrated at
    ``aspect_ratio``, as liblensfun applies it: the calibration frame's
    diagonal (its corner at hypot(aspect, 1) units) matched to the frame's
    (3606 px from the centre). test_fix_liblensfun holds this to
    liblensfun's own Modifier."""
    aspect = max(aspect_ratio, 1 / aspect_ratio)
    return math.hypot(3000, 2000) / math.hypot(aspect, 1)


def exact_d(model: str, texts: dict[str, str]) -> sympy.Poly:
    """D(r) from Lensfun's formulas, coefficients exactly as written."""
    q = {name: sympy.Rational(Fraction(text)) for name, text in texts.items()}
    if model == "ptlens":
        a, b, c = q["a"], q["b"], q["c"]
        return sympy.Poly(R * (a * R**3 + b * R**2 + c * R + 1 - a - b - c), R)
    if model == "poly3":
        return sympy.Poly(R * (1 - q["k1"] + q["k1"] * R**2), R)
    return sympy.Poly(R * (1 + q["k1"] * R**2 + q["k2"] * R**4), R)


def exact_corner(aspect: float) -> sympy.Expr:
    ratio = sympy.Rational(Fraction(aspect).limit_denominator(1000))
    return sympy.sqrt(ratio**2 + 1)


def increasing_up_to(d: sympy.Poly, target: float) -> bool:
    """D' > 0 on [0, target] (target may be inf), decided exactly."""
    slope = d.diff(R)
    if not slope.eval(0) > 0:
        return False
    limit = sympy.oo if math.isinf(target) else sympy.Rational(Fraction(target))
    return not any(0 < root <= limit for root in sympy.real_roots(slope))


def reach_before_fold(d: sympy.Poly) -> sympy.Expr:
    """D at its first local maximum (exact algebraic number), or oo."""
    slope = d.diff(R)
    positive = [root for root in sympy.real_roots(slope) if root > 0]
    if not positive:
        return sympy.oo if d.LC() > 0 else d.eval(0)
    return d.eval(min(positive))


def texts_of(result, new: bool) -> dict[str, str]:
    return dict(zip(result.names, result.new_texts if new else result.old_texts, strict=True))


@pytest.fixture(scope="module")
def database(bundled_db, tmp_path_factory):
    """A copy of the bundled database, fixed with the default settings (not written)."""
    copy = tmp_path_factory.mktemp("fix") / "db"
    shutil.copytree(bundled_db, copy)
    results, patches = fix.fix(str(copy))
    return copy, results, patches


@pytest.fixture(scope="module")
def results(database):
    return database[1]


@pytest.fixture(scope="module")
def scanned(database):
    """`lensaudit scan --format csv` of the database copy: rows by (file, line)."""
    output = CliRunner().invoke(main, ["scan", "--no-cache", "-f", "csv", str(database[0])]).output
    return {(row["file"], int(row["line"])): row for row in csv.DictReader(io.StringIO(output))}


def image_radius(scanned, result) -> sympy.Expr:
    """The radius of the image the entry is judged against, as `scan` gives it.

    Exact when it is the frame's corner, else the rational value of the float.
    """
    radius = float(scanned[(result.entry.file, result.entry.line)]["r_corner"])
    corner = exact_corner(result.entry.aspect_ratio)
    if radius == pytest.approx(float(corner), rel=1e-15):
        return corner
    return sympy.Rational(Fraction(radius))


@pytest.fixture(scope="module")
def patched(database, tmp_path_factory):
    """A second copy with the patches written: (directory, original bytes by name)."""
    source, _, patches = database
    copy = tmp_path_factory.mktemp("patched") / "db"
    shutil.copytree(source, copy)
    originals = {}
    for patch in patches:
        path = copy / patch.name
        originals[patch.name] = path.read_bytes()
        write(type(patch)(path, patch.name, patch.original, patch.patched))
    return copy, originals


def test_the_entries_below_checks_margin_are_the_ones_examined(results, scanned):
    flagged = {
        key
        for key, row in scanned.items()
        if row["r_normalized"] not in ("", "inf") and Fraction(row["r_normalized"]) < MARGIN
    }
    assert {(r.entry.file, r.entry.line) for r in results} == flagged
    # Those that fold inside their image among them, and some just outside it.
    folding = {key for key, row in scanned.items() if row["folds_in_image"] == "true"}
    assert folding < flagged
    # The rectilinear ones of the README's seven (the paper's Tokina among them).
    lenses = {r.entry.lens for r in results}
    assert {
        "Tokina 11-16mm f/2.8 AT-X 116 AF Pro DX",
        "Olympus M.Zuiko Digital ED 14-42mm f/3.5-5.6",
        "P30 Pro",
        "Samsung Galaxy S21 ultrawide",
    } <= lenses


def test_every_folding_entry_is_fixed_or_says_why(results):
    for result in results:
        if result.status == fix.STATUS_FIXED:
            assert result.max_change_px <= TOLERANCE and result.message == ""
        else:
            assert result.status == fix.STATUS_BEYOND_TOLERANCE, result.where
            assert f"{result.max_change_px:.0f} px" in result.message
            assert "50 px tolerance" in result.message


def test_the_rectilinear_ptlens_entries_are_fixed_within_tolerance(results, scanned):
    rectilinear = [
        r for r in results if r.entry.type == "rectilinear" and r.entry.model == "ptlens"
    ]
    expected = [
        row
        for row in scanned.values()
        if row["type"] == "rectilinear"
        and row["model"] == "ptlens"
        and row["r_normalized"] not in ("", "inf")
        and Fraction(row["r_normalized"]) < MARGIN
    ]
    assert len(rectilinear) == len(expected) >= 3
    assert all(r.status == fix.STATUS_FIXED for r in rectilinear)


def test_new_coefficients_increase_up_to_the_target_exactly(results, scanned):
    for result in results:
        d = exact_d(result.entry.model, texts_of(result, new=True))
        assert increasing_up_to(d, result.goal.target), result.where
        radius = float(image_radius(scanned, result))
        assert result.goal.target >= radius * (1 - 1e-15)


def test_the_old_coefficients_fold_before_reaching_the_margin_exactly(results, scanned):
    for result in results:
        d = exact_d(result.entry.model, texts_of(result, new=False))
        assert reach_before_fold(d) < MARGIN * image_radius(scanned, result), result.where


def test_new_coefficients_reach_the_margin_before_folding_exactly(results, scanned):
    for result in results:
        d = exact_d(result.entry.model, texts_of(result, new=True))
        radius = image_radius(scanned, result)
        assert sympy.N(reach_before_fold(d) - MARGIN * radius, 30) >= 0, result.where


def test_the_reported_maximum_change_is_the_exact_maximum(results, scanned):
    for result in results:
        change = exact_d(result.entry.model, texts_of(result, new=True)) - exact_d(
            result.entry.model, texts_of(result, new=False)
        )
        corner = image_radius(scanned, result)
        points = [sympy.Integer(0), corner] + [
            root for root in sympy.real_roots(change.diff(R)) if 0 < root < corner
        ]
        largest = max(abs(sympy.N(change.as_expr().subs(R, p), 30)) for p in points)
        unit = px_per_unit(result.entry.aspect_ratio)
        assert result.max_change_px == pytest.approx(float(largest) * unit, rel=1e-9)
        frame_corner = float(exact_corner(result.entry.aspect_ratio))
        assert result.max_change_half_diagonal == pytest.approx(
            float(largest) / frame_corner, rel=1e-9
        )


def mean_square_change(result, radius: float) -> float:
    """Mean of the squared change of D over the quarter frame within ``radius`` (scipy)."""
    from scipy.integrate import dblquad

    change = sympy.lambdify(
        R,
        (
            exact_d(result.entry.model, texts_of(result, new=True))
            - exact_d(result.entry.model, texts_of(result, new=False))
        ).as_expr(),
    )
    aspect = result.entry.aspect_ratio
    width = min(aspect, radius)

    def height(x: float) -> float:
        return min(1.0, math.sqrt(max(radius * radius - x * x, 0.0)))

    integral, _ = dblquad(
        lambda y, x: change(math.hypot(x, y)) ** 2, 0, width, 0, height, epsabs=0, epsrel=1e-11
    )
    area, _ = dblquad(lambda y, x: 1.0, 0, width, 0, height, epsabs=0, epsrel=1e-12)
    return integral / area


def test_the_reported_rms_change_is_the_mean_over_the_image(results, scanned):
    for result in results:
        radius = float(image_radius(scanned, result))
        unit = px_per_unit(result.entry.aspect_ratio)
        expected = math.sqrt(mean_square_change(result, radius)) * unit
        assert result.rms_change_px == pytest.approx(expected, rel=1e-7), result.where


def test_within_a_smaller_image_radius_changes_are_measured_inside_it():
    xml = lens_xml(
        '<distortion model="ptlens" focal="4.5" a="-0.21693" b="-0.44076" c="-0.47357"/>'
    )
    (entry,) = read.read_bytes(xml.encode(), "t.xml").entries()
    result = fix.fix_entry(entry, image_radius=1.0, tolerance=math.inf)
    assert result.goal.r_corner == 1.0 and result.goal.target == pytest.approx(1.1)
    d = exact_d("ptlens", texts_of(result, new=True))
    assert increasing_up_to(d, 1.1)
    assert sympy.N(reach_before_fold(d) - MARGIN, 30) >= 0
    expected = math.sqrt(mean_square_change(result, 1.0)) * px_per_unit(entry.aspect_ratio)
    assert result.rms_change_px == pytest.approx(expected, rel=1e-7)


def significant_digits(text: str) -> int:
    mantissa = text.lower().partition("e")[0].lstrip("+-").replace(".", "")
    return len(mantissa.lstrip("0"))


def written_decimals(text: str) -> int:
    mantissa, _, exponent = text.lower().partition("e")
    return len(mantissa.partition(".")[2]) - int(exponent or 0)


def test_new_coefficients_keep_the_files_decimals_and_five_significant_digits(results):
    for result in results:
        decimals = max(written_decimals(t) for t in result.old_texts)
        for text in result.new_texts:
            assert written_decimals(text) >= decimals, (result.where, text)
            if float(text) != 0:
                assert significant_digits(text) >= 5, (result.where, text)


def test_writing_changes_only_the_coefficient_values(database, patched):
    directory, originals = patched
    _, results, _ = database
    assert len(originals) == sum(r.status == fix.STATUS_FIXED for r in results)
    for name, original in originals.items():
        expected = original.decode("utf-8").split("\n")
        for result in results:
            if result.entry.file != name or result.status != fix.STATUS_FIXED:
                continue
            line = expected[result.entry.line - 1]
            for attribute, old, new in zip(
                result.names, result.old_texts, result.new_texts, strict=True
            ):
                assert line.count(f' {attribute}="{old}"') == 1
                line = line.replace(f' {attribute}="{old}"', f' {attribute}="{new}"')
            expected[result.entry.line - 1] = line
        assert (directory / name).read_bytes() == "\n".join(expected).encode("utf-8")


def test_the_patched_database_no_longer_folds_where_fixed(database, patched):
    _, results, _ = database
    audit = run(str(patched[0]))
    flags = audit.metrics.folds_in_image
    folding = {(e.file, e.line) for e, f in zip(audit.entries, flags, strict=True) if f}
    for result in results:
        folds = (result.entry.file, result.entry.line) in folding
        # Fixed: no longer folds; not fixed: as before (inside its image, or just outside).
        assert folds == (not result.fixed and result.r_normalized_before < 1), result.where


def test_fixing_twice_changes_nothing_the_second_time(patched):
    directory, _ = patched
    before = {p.name: p.read_bytes() for p in directory.iterdir()}
    results, patches = fix.fix(str(directory))
    assert all(r.status != fix.STATUS_FIXED for r in results)
    assert not any(p.changed for p in patches)
    assert {p.name: p.read_bytes() for p in directory.iterdir()} == before


def entry_from(xml: str, tmp_path, **options):
    path = tmp_path / "one.xml"
    path.write_text(xml)
    audit = run(str(path))
    indices = fix.select(audit, margin=options.get("margin", 1.0))
    assert len(indices) == 1
    sources = fix.read_sources(audit, indices)
    (result,) = fix.fix_audit(audit, indices, sources=sources, **options)
    return path, result, fix.patches([result], sources)


def test_an_infinite_target_gives_a_model_that_never_folds(tmp_path):
    xml = lens_xml('<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>')
    _, result, _ = entry_from(xml, tmp_path, target=math.inf, tolerance=math.inf)
    assert result.status == fix.STATUS_FIXED and math.isinf(result.r_max_after)
    assert increasing_up_to(exact_d("ptlens", texts_of(result, new=True)), math.inf)


def test_a_margin_above_one_reaches_beyond_the_corner(tmp_path):
    xml = lens_xml('<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>')
    _, result, _ = entry_from(xml, tmp_path, margin=1.1, tolerance=math.inf)
    corner = exact_corner(1.5)
    d = exact_d("ptlens", texts_of(result, new=True))
    assert increasing_up_to(d, float(sympy.N(corner * sympy.Rational(11, 10), 30)) + 1e-12)
    assert sympy.N(reach_before_fold(d) - corner * sympy.Rational(11, 10), 30) >= 0


def test_a_poly5_model_is_refitted_as_poly5(tmp_path):
    xml = lens_xml('<distortion model="poly5" focal="10" k1="-0.1" k2="-0.01"/>')
    _, result, patches = entry_from(xml, tmp_path, tolerance=math.inf)
    assert result.names == ("k1", "k2") and result.status == fix.STATUS_FIXED
    d = exact_d("poly5", texts_of(result, new=True))
    assert increasing_up_to(d, result.goal.target)
    assert sympy.N(reach_before_fold(d) - exact_corner(1.5), 30) >= 0
    assert len(patches) == 1


def test_a_coefficient_missing_from_the_file_is_added(tmp_path):
    xml = lens_xml('<distortion model="ptlens" focal="11" a="-0.03" c="0.005"/>')
    path, result, patches = entry_from(xml, tmp_path, tolerance=math.inf)
    assert result.old_texts == ("-0.03", "0", "0.005")
    write(patches[0])
    (entry,) = read.read(path).entries()
    assert entry.status == STATUS_OK
    assert (entry.a, entry.b, entry.c) == tuple(float(t) for t in result.new_texts)
    new_line = path.read_text().splitlines()[entry.line - 1]
    assert re.search(r' c="[-0-9.]+" b="[-0-9.]+"/>', new_line)


def test_an_entry_moved_since_the_audit_is_not_patched_and_says_why(tmp_path):
    xml = lens_xml('<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>')
    path = tmp_path / "one.xml"
    path.write_text(xml)
    audit = run(str(path))
    path.write_text("\n" + xml)
    indices = fix.select(audit)
    sources = fix.read_sources(audit, indices)
    (result,) = fix.fix_audit(audit, indices, sources=sources)
    assert result.status == fix.STATUS_NOT_LOCATED
    assert "no <distortion> element ends on this line" in result.message
    assert "changed since it was read" in result.message
    assert fix.patches([result], sources) == []


@pytest.mark.parametrize("line_end", ["\r\n", "\r"], ids=["CRLF", "CR"])
def test_a_file_with_other_line_ends_is_patched_on_the_readers_line(tmp_path, line_end):
    xml = lens_xml('<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>')
    path = tmp_path / "one.xml"
    path.write_bytes(xml.replace("\n", line_end).encode())
    audit = run(str(path))
    indices = fix.select(audit)
    sources = fix.read_sources(audit, indices)
    (result,) = fix.fix_audit(audit, indices, sources=sources, tolerance=math.inf)
    assert result.status == fix.STATUS_FIXED
    (patch,) = fix.patches([result], sources)
    assert b'a="-0.024"' not in patch.patched  # the new coefficients are written
    assert patch.patched.count(line_end.encode()) == patch.original.count(line_end.encode())


def test_an_element_written_with_character_references_is_not_patched(tmp_path):
    xml = lens_xml('<distortion model="ptlens" focal="11" a="&#45;0.024" b="-0.002" c="0.005"/>')
    path = tmp_path / "one.xml"
    path.write_text(xml)
    audit = run(str(path))
    indices = fix.select(audit)
    (result,) = fix.fix_audit(audit, indices, sources=fix.read_sources(audit, indices))
    assert result.status == fix.STATUS_NOT_LOCATED and "character references" in result.message
    assert result.new  # the refit is still shown


def test_a_file_changed_between_reading_and_writing_is_not_written(tmp_path):
    xml = lens_xml('<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>')
    path, _, patches = entry_from(xml, tmp_path)
    path.write_text(xml + "<!-- edited -->\n")
    with pytest.raises(PatchError, match="changed since it was read"):
        write(patches[0])
    assert path.read_text() == xml + "<!-- edited -->\n"


@pytest.mark.parametrize(
    ("value", "decimals", "template", "expected"),
    [
        (-0.0209301, 6, "-0.024", "-0.020930"),
        (0.18055, 5, "0.188", "0.18055"),
        (-8.61234e-05, 9, "-8.6e-05", "-8.6123e-05"),
        (1.5e-3, 5, "2E-4", "1.50E-3"),
        (-1e-9, 3, "0.000", "0.000"),
    ],
)
def test_numbers_are_written_in_the_files_style(value, decimals, template, expected):
    assert fix.format_like(value, decimals, template) == expected


@pytest.mark.parametrize(
    ("text", "decimals"), [("-0.024", 3), ("-8.6e-05", 6), ("12", 0), ("1.5e3", 0)]
)
def test_decimals_count_the_exponent(text, decimals):
    assert fix.decimals_of(text) == decimals


_coefficient = st.decimals(min_value=-1, max_value=1, places=4).map(str)


@settings(max_examples=12, deadline=None)
@given(_coefficient, _coefficient, _coefficient, st.sampled_from([1.5, 4 / 3]))
def test_any_ptlens_fold_is_refitted_to_meet_its_goal_exactly(a, b, c, aspect):
    m = compute(
        ["ptlens"], [float(a)], [float(b)], [float(c)], [0], [0], [1], [aspect], [10], [True]
    )
    assume(
        bool(m.folds_in_image[0])
        and float(Fraction(1) - Fraction(a) - Fraction(b) - Fraction(c)) > 0.05
    )
    text = (
        f"<lensdatabase><lens><maker>T</maker><model>T</model><aspect-ratio>{aspect!r}</aspect-ratio>"
        f'<calibration><distortion model="ptlens" focal="10" a="{a}" b="{b}" c="{c}"/>'
        "</calibration></lens></lensdatabase>"
    )
    (entry,) = read.read_bytes(text.encode(), "t.xml").entries()
    result = fix.fix_entry(entry, tolerance=math.inf, texts={"a": a, "b": b, "c": c})
    assert result.status == fix.STATUS_FIXED, result.message
    d = exact_d("ptlens", texts_of(result, new=True))
    assert increasing_up_to(d, result.goal.target)
    assert sympy.N(reach_before_fold(d) - exact_corner(aspect), 30) >= 0


# The command line.


@pytest.fixture
def runner():
    return CliRunner()


def test_help_states_the_frame_and_exit_status(runner):
    result = runner.invoke(main, ["fix", "--help"])
    assert result.exit_code == 0
    assert "6000x4000" in result.output and "Exit status" in result.output


def test_fix_is_listed_among_the_commands(runner):
    assert "fix" in runner.invoke(main, ["--help"]).output


def test_a_missing_path_is_one_line_and_exit_2(runner, tmp_path):
    result = runner.invoke(main, ["fix", str(tmp_path / "nope")])
    assert result.exit_code == 2
    assert result.output.strip().count("\n") == 0 and "no such file" in result.output


@pytest.mark.parametrize(
    "option", [["--margin", "0"], ["--margin", "nan"], ["--target", "-1"], ["--tolerance", "-5"]]
)
def test_bad_numbers_are_one_line_and_exit_2(runner, option, tmp_path):
    result = runner.invoke(main, ["fix", str(tmp_path), *option])
    assert result.exit_code == 2
    assert result.output.startswith("lensaudit: error: " + option[0])


def test_writing_the_bundled_database_is_refused(runner):
    result = runner.invoke(main, ["fix", "--write"])
    assert result.exit_code == 2 and "give the database PATH" in result.output


@pytest.mark.parametrize("given", ["directory", "file", "link"])
def test_writing_the_bundled_database_by_its_path_is_refused(runner, tmp_path, monkeypatch, given):
    # A stand-in for lensfunpy's database, so that nothing installed is at stake.
    from lensaudit.read import paths

    bundled = tmp_path / "db_files"
    bundled.mkdir()
    path = bundled / "one.xml"
    path.write_text(
        lens_xml('<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>')
    )
    before = path.read_bytes()
    monkeypatch.setattr(paths, "bundled_database_path", lambda: bundled)
    (tmp_path / "link").symlink_to(bundled)
    target = {"directory": bundled, "file": path, "link": tmp_path / "link"}[given]
    result = runner.invoke(main, ["fix", str(target), "--write", "--no-cache"])
    assert result.exit_code == 2, result.output
    assert "is the database bundled with lensfunpy, which is not written" in result.output
    assert path.read_bytes() == before
    # Without --write, the same database is refitted as any other.
    assert runner.invoke(main, ["fix", str(target), "--no-cache"]).exit_code == 0


@pytest.mark.parametrize(
    ("distortion", "options"),
    [
        ('<distortion model="poly3" focal="10" k1="1e308"/>', []),
        ('<distortion model="ptlens" focal="11" a="1e308" b="-0.002" c="0.005"/>', []),
        ('<distortion model="poly3" focal="16" k1="-0.11"/>', ["--margin", "1e308"]),
    ],
)
def test_values_near_the_largest_double_are_no_solution_without_a_warning(
    runner, tmp_path, distortion, options
):
    (tmp_path / "db").mkdir()
    (tmp_path / "db" / "one.xml").write_text(lens_xml(distortion))
    found = {}
    for output_format in ("csv", "json", "table"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a warning would end the command in a traceback
            result = runner.invoke(
                main, ["fix", str(tmp_path / "db"), "-f", output_format, *options]
            )
        assert result.exit_code == 0, result.output
        found[output_format] = result.output
    (row,) = csv.DictReader(io.StringIO(found["csv"]))
    assert row["status"] == "no_solution" and row["k1_new"] == row["a_new"] == ""
    (entry,) = json.loads(found["json"])["entries"]
    assert entry["status"] == "no_solution"
    assert "no_solution" in found["table"]


def test_a_target_near_the_largest_double_gets_the_model_that_never_folds(runner, tmp_path):
    # A refit valid for r = inf is valid for any finite target, however large.
    (tmp_path / "db").mkdir()
    (tmp_path / "db" / "one.xml").write_text(
        lens_xml('<distortion model="poly3" focal="16" k1="-0.11"/>')
    )
    found = {}
    for target in ("1e308", "inf"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            result = runner.invoke(
                main, ["fix", str(tmp_path / "db"), "-f", "csv", "--target", target]
            )
        assert result.exit_code == 0, result.output
        (found[target],) = csv.DictReader(io.StringIO(result.output))
    assert found["1e308"]["status"] != "no_solution"
    assert found["1e308"]["k1_new"] == found["inf"]["k1_new"] != ""
    assert float(found["1e308"]["r_max_after"]) == math.inf


def test_the_command_prints_a_diff_and_writes_nothing(runner, tmp_path):
    xml = lens_xml('<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>')
    (tmp_path / "db").mkdir()
    path = tmp_path / "db" / "one.xml"
    path.write_text(xml)
    result = runner.invoke(main, ["fix", str(path.parent)])
    assert result.exit_code == 0, result.output
    assert "--- a/one.xml" in result.output and "1 fixed, 0 not fixed" in result.output
    assert path.read_text() == xml


def test_write_then_run_again_is_a_no_op(runner, tmp_path):
    xml = lens_xml(
        '<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>',
        '<distortion model="poly3" focal="14" k1="-0.079"/>',
    )
    (tmp_path / "db").mkdir()
    path = tmp_path / "db" / "one.xml"
    path.write_text(xml)
    first = runner.invoke(main, ["fix", str(path.parent), "--write", "--tolerance", "1000"])
    assert first.exit_code == 0, first.output
    assert "Written: one.xml" in first.output
    after = path.read_bytes()
    assert after != xml.encode()
    second = runner.invoke(main, ["fix", str(path.parent), "--write"])
    assert second.exit_code == 0
    assert "0 entries with r_normalized < 1" in second.output
    assert path.read_bytes() == after


def test_csv_has_one_row_per_folding_entry(runner, tmp_path):
    xml = lens_xml(
        '<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>',
        '<distortion model="poly3" focal="14" k1="0.01"/>',
        '<distortion model="poly3" focal="18" k1="-0.079"/>',
    )
    (tmp_path / "db").mkdir()
    (tmp_path / "db" / "one.xml").write_text(xml)
    result = runner.invoke(main, ["fix", str(tmp_path / "db"), "-f", "csv"])
    rows = list(csv.DictReader(io.StringIO(result.output)))
    assert [(r["focal"], r["model"], r["status"]) for r in rows] == [
        ("11.0", "ptlens", "fixed"),
        ("18.0", "poly3", "beyond_tolerance"),
    ]
    assert rows[0]["a_new"] and rows[0]["k1_new"] == "" and rows[0]["c_old"] == "0.005"


def test_json_holds_results_and_diff(runner, tmp_path):
    xml = lens_xml('<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>')
    (tmp_path / "db").mkdir()
    (tmp_path / "db" / "one.xml").write_text(xml)
    result = runner.invoke(main, ["fix", str(tmp_path / "db"), "-f", "json"])
    document = json.loads(result.output)
    (entry,) = document["entries"]
    assert entry["status"] == "fixed" and isinstance(entry["a_new"], float)
    assert document["diff"].startswith("--- a/one.xml")
    assert "6000x4000" in document["units"]["changes"]


def test_write_leaves_every_file_alone_when_one_changed_meanwhile(runner, tmp_path, monkeypatch):
    xml = lens_xml('<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>')
    (tmp_path / "db").mkdir()
    first, second = tmp_path / "db" / "a.xml", tmp_path / "db" / "b.xml"
    first.write_text(xml)
    second.write_text(xml)
    computed = fix.patches

    def edited_meanwhile(*args, **kwargs):
        found = computed(*args, **kwargs)
        second.write_text(xml + "<!-- edited -->\n")
        return found

    monkeypatch.setattr(fix, "patches", edited_meanwhile)
    result = runner.invoke(main, ["fix", str(tmp_path / "db"), "--write"])
    assert result.exit_code == 2
    assert (
        result.output
        == "lensaudit: error: b.xml: the file changed since it was read; nothing written\n"
    )
    assert first.read_text() == xml


def test_a_fisheye_judged_against_the_frame_corner_is_told_about_image_circles(tmp_path):
    xml = lens_xml(
        '<distortion model="ptlens" focal="4.5" a="-0.21693" b="-0.44076" c="-0.47357"/>',
        extra="<type>fisheye</type>",
    )
    _, result, _ = entry_from(xml, tmp_path)
    assert result.status == fix.STATUS_BEYOND_TOLERANCE
    assert "image circle" in result.message and "type fisheye" in result.message


def exact_smallest_slope(d: sympy.Poly, reach: sympy.Expr) -> sympy.Expr:
    """The smallest D' from 0 to where D first reaches ``reach`` (an algebraic
    number whose square is rational): D rises from 0 until its first critical
    point, so that radius is the first positive root of D^2 - reach^2, isolated
    exactly (sympy's continued fractions on rationals) to within 1e-40."""
    slope = d.diff(R)
    fold = [root for root in sympy.real_roots(slope) if root > 0]
    if fold:
        assert d.eval(min(fold)) >= reach
    crossing = d**2 - sympy.Rational(reach**2)
    (low, high), _ = crossing.intervals(eps=sympy.Rational(1, 10**40), inf=0)[0]
    assert 0 <= low and high - low <= sympy.Rational(1, 10**40)
    assert not fold or low <= min(fold)
    points = [sympy.Integer(0), high] + [
        root for root in sympy.real_roots(slope.diff(R)) if 0 < root < high
    ]
    return min(slope.eval(p) for p in points)


def test_the_smallest_slope_up_to_the_margin_is_exact_and_kept_above_the_floor(results, scanned):
    for result in results:
        d = exact_d(result.entry.model, texts_of(result, new=True))
        reach = MARGIN * image_radius(scanned, result)
        smallest = sympy.N(exact_smallest_slope(d, reach), 30)
        assert result.min_slope_after == pytest.approx(float(smallest), rel=1e-9), result.where
        assert smallest >= sympy.Rational(1, 5), result.where


def test_entries_fix_fixes_pass_check_with_no_fold_finding(database, patched):
    _, results, _ = database
    directory, _ = patched
    output = CliRunner().invoke(main, ["check", "--no-cache", "-f", "json", str(directory)])
    findings = json.loads(output.output)["findings"]
    fixed = {(r.entry.file, r.entry.line) for r in results if r.fixed}
    assert len(fixed) >= 4
    folds = {
        (Path(f["file"]).name, f["line"])
        for f in findings
        if f["code"].startswith("fold-")  # fold-in-image, fold-near-image, fold-outside-image
    }
    assert not fixed & folds
    # ... while the entries it could not fix within the tolerance still have theirs.
    assert {(r.entry.file, r.entry.line) for r in results if not r.fixed} <= folds


def test_a_lens_filter_that_matches_nothing_is_refused(bundled_db):
    none = CliRunner().invoke(main, ["fix", "--no-cache", "--lens", "Nikkor 999mm"])
    assert none.exit_code == 2
    assert "no audited entry" in none.output and "Nikkor 999mm" in none.output
    unfolding = CliRunner().invoke(main, ["fix", "--no-cache", "--lens", "Nikkor", "--focal", "50"])
    assert unfolding.exit_code == 0 and "0 entries" in unfolding.output


def test_progress_is_told_once_per_entry_refitted(tmp_path):
    lines = [
        f'<distortion model="ptlens" focal="{focal}" a="-0.024" b="-0.002" c="0.005"/>'
        for focal in (11, 12, 13)
    ]
    (tmp_path / "db").mkdir()
    (tmp_path / "db" / "one.xml").write_text(lens_xml(*lines))
    audit = run(tmp_path / "db")
    indices = fix.select(audit)
    told = []
    results = fix.fix_audit(audit, indices, progress=lambda done, total: told.append((done, total)))
    assert len(results) == 3 and told == [(1, 3), (2, 3), (3, 3)]


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-be", "utf-32"])
def test_a_utf16_file_is_refitted_and_said_not_patched_for_its_encoding(runner, tmp_path, encoding):
    text = lens_xml('<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>')
    declared = '<?xml version="1.0" encoding="UTF-16"?>\n' if encoding != "utf-32" else ""
    (tmp_path / "db").mkdir()
    path = tmp_path / "db" / "one.xml"
    if encoding == "utf-16-be":  # with its byte order mark, as an editor writes it
        path.write_bytes(b"\xfe\xff" + (declared + text).encode(encoding))
    else:
        path.write_bytes((declared + text).encode(encoding))
    before = path.read_bytes()
    result = runner.invoke(main, ["fix", str(tmp_path / "db"), "-f", "csv", "--write"])
    assert path.read_bytes() == before
    rows = list(csv.DictReader(io.StringIO(result.output)))
    if not rows:  # a UTF-32 file is not read at all: nothing to refit
        assert result.exit_code == 2 and "one.xml" in result.output
        return
    assert result.exit_code == 0, result.output
    assert [row["status"] for row in rows] == ["not_located"]
    assert "UTF-16 or UTF-32" in rows[0]["message"] and rows[0]["a_new"] != ""


def test_the_refits_measures_refuse_what_is_not_a_model_in_one_line():
    from lensaudit import refit

    with pytest.raises(ValueError, match="unknown model 'acm'"):
        refit.change_of_distortion("acm", [0.01], [0.0], 1.5)
    with pytest.raises(ValueError, match="not all finite numbers"):
        refit.change_of_distortion("ptlens", [math.nan, -0.05, 0.02], [0.0, 0.0, 0.0], 1.5)
    with pytest.raises(ValueError, match="not all finite numbers"):
        refit.smallest_slope("poly3", (math.nan,), 1.9, 3.0)
    for aspect in (0.0, -1.5, math.inf, math.nan):
        with pytest.raises(ValueError, match="aspect ratio"):
            refit.change_of_distortion("poly3", [0.01], [0.0], aspect)
