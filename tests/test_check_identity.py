"""`lensaudit check --baseline`: what makes a finding the same finding as the baseline's.

Each test builds a baseline and a changed database from a few hand-made
lenses, so that which findings the change introduced is known by
construction: a finding is new exactly when the change made it.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lensaudit.check import check

FOLDING = '<distortion model="poly3" focal="10" k1="-0.3"/>'  # r_normalized 0.578
FOLDING_TOO = '<distortion model="poly3" focal="14" k1="-0.25"/>'  # r_normalized 0.655
FINE = '<distortion model="poly3" focal="20" k1="0.01"/>'  # r_max infinite


def lens(model: str, *distortions: str, maker: str = "Test", mount: str = "Mount") -> str:
    body = "".join(f"      {d}\n" for d in distortions)
    return (
        f"  <lens>\n    <maker>{maker}</maker>\n    <model>{model}</model>\n"
        f"    <mount>{mount}</mount>\n    <cropfactor>1.5</cropfactor>\n"
        f"    <calibration>\n{body}    </calibration>\n  </lens>\n"
    )


def xml(*lenses: str) -> str:
    return '<lensdatabase version="2">\n' + "".join(lenses) + "</lensdatabase>\n"


def databases(tmp_path: Path, before: dict[str, str], after: dict[str, str]) -> tuple[Path, Path]:
    """Two database directories: ``before`` and ``after`` map file names to XML."""
    for name, files in (("before", before), ("after", after)):
        (tmp_path / name).mkdir()
        for file, text in files.items():
            (tmp_path / name / file).write_text(text, encoding="utf-8")
    return tmp_path / "before", tmp_path / "after"


def compare(tmp_path: Path, before: dict[str, str], after: dict[str, str]):
    """``after`` checked against ``before`` as its baseline."""
    baseline, changed = databases(tmp_path, before, after)
    return check(changed, baseline=baseline)


def new(result) -> list[tuple[str, str, int]]:
    """(code, file, line) of the findings that are not known from the baseline."""
    return [(f.code, Path(f.file).name, f.line) for f in result.findings if not f.known]


def line_of(text: str, fragment: str, occurrence: int = 1) -> int:
    """Line number (from 1) of the n-th line holding ``fragment``."""
    lines = [i for i, line in enumerate(text.splitlines(), 1) if fragment in line]
    return lines[occurrence - 1]


def test_a_change_to_another_lens_leaves_a_known_fold_known(tmp_path):
    before = xml(lens("Lens A", FINE), lens("Lens B", FOLDING))
    after = xml(lens("Lens A", FINE, FINE.replace("20", "24")), lens("Lens B", FOLDING))
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert new(result) == [] and result.resolved == 0


def test_a_known_fold_stays_known_when_its_lens_is_renamed(tmp_path):
    before = xml(lens("Lens B", FOLDING))
    after = xml(lens("Lens B Mark II", FOLDING))
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert new(result) == [] and result.resolved == 0


def test_a_known_fold_stays_known_when_its_lens_name_changes_case_and_spacing(tmp_path):
    before = xml(lens("Canon RF200-800mm F6.3-9", FOLDING, maker="Canon"))
    after = xml(lens("Canon RF 200-800mm  f6.3-9", FOLDING, maker="CANON"))
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert new(result) == [] and result.resolved == 0


def test_a_copy_of_a_known_folding_entry_under_a_new_lens_is_new(tmp_path):
    before = xml(lens("Lens B", FOLDING))
    after = xml(lens("Lens B", FOLDING), lens("Lens C", FOLDING))
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert new(result) == [("fold-in-image", "a.xml", line_of(after, "focal", 2))]


def test_a_copy_of_a_known_folding_entry_is_new_when_the_change_also_fixes_the_original(
    tmp_path,
):
    # A new lens copied from an old one with its folding entry, and the old
    # entry refitted in the same change: the old lens keeps its name, so the
    # baseline's fold is resolved, not the copy's.
    refitted = FOLDING.replace("-0.3", "0.01")
    before = xml(lens("Lens B", FOLDING))
    after = xml(lens("Lens B", refitted), lens("Lens B Mark II", FOLDING))
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert new(result) == [("fold-in-image", "a.xml", line_of(after, "focal", 2))]
    assert result.resolved == 1


def test_a_renamed_lens_keeps_its_fold_known_when_another_lens_takes_no_name_of_it(tmp_path):
    # The rename, with an entry of another lens edited in the same change.
    before = xml(lens("Lens A", FINE), lens("Lens B", FOLDING))
    after = xml(lens("Lens A", FINE.replace("0.01", "0.02")), lens("Lens B Mark II", FOLDING))
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert new(result) == [] and result.resolved == 0


def test_a_known_fold_moved_to_another_file_stays_known(tmp_path):
    folding = lens("Lens B", FOLDING)
    before = {"a.xml": xml(folding, lens("Lens A", FINE)), "b.xml": xml(lens("Lens Z", FINE))}
    after = {"a.xml": xml(lens("Lens A", FINE)), "b.xml": xml(lens("Lens Z", FINE), folding)}
    result = compare(tmp_path, before, after)
    assert new(result) == [] and result.resolved == 0


def test_a_known_duplicate_focal_stays_known_when_another_lens_is_edited(tmp_path):
    twice = lens("Lens B", FINE, FINE.replace("0.01", "0.02"))
    before = xml(lens("Lens A", FINE), twice)
    after = xml(lens("Lens A", FINE, FOLDING.replace("-0.3", "0.03")), twice)
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert [f.code for f in result.findings] == ["duplicate-focal"]
    assert new(result) == []


def test_a_known_duplicate_focal_stays_known_when_its_lens_is_renamed(tmp_path):
    twice = (FINE, FINE.replace("0.01", "0.02"))
    before = xml(lens("Canon RF200-800mm", *twice))
    after = xml(lens("Canon RF 200-800mm", *twice))
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert new(result) == [] and result.resolved == 0


def test_editing_one_entry_of_a_known_duplicate_focal_keeps_the_duplicate_known(tmp_path):
    before = xml(lens("Lens B", FINE, FINE.replace("0.01", "0.02")))
    after = xml(lens("Lens B", FINE, FINE.replace("0.01", "0.03")))
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert [(f.code, f.known) for f in result.findings] == [("duplicate-focal", True)]


def test_a_known_duplicate_focal_stays_known_when_its_lens_gets_an_aspect_ratio(tmp_path):
    before = xml(lens("Lens B", FINE, FINE.replace("0.01", "0.02")))
    after = before.replace("</mount>", "</mount><aspect-ratio>4:3</aspect-ratio>")
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert [(f.code, f.known) for f in result.findings] == [("duplicate-focal", True)]


def test_editing_a_known_duplicate_lens_keeps_the_duplicate_known(tmp_path):
    before = xml(lens("Lens A", FINE), lens("Lens A", FOLDING.replace("-0.3", "0.02")))
    after = xml(
        lens("Lens A", FINE).replace("</mount>", "</mount><aspect-ratio>4:3</aspect-ratio>"),
        lens("Lens A", FOLDING.replace("-0.3", "0.02")),
    )
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert [(f.code, f.known) for f in result.findings] == [("duplicate-lens", True)]


def test_a_known_duplicate_lens_stays_known_when_both_are_renamed(tmp_path):
    before = xml(lens("Standard", FINE, maker="Fuji"), lens("Standard", FOLDING, maker="Fuji"))
    after = before.replace("<maker>Fuji</maker>", "<maker>Fujifilm</maker>")
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert [(f.code, f.known) for f in result.findings] == [
        ("duplicate-lens", True),
        ("fold-in-image", True),
    ]


def test_a_third_definition_of_a_known_duplicate_lens_is_new_at_the_third(tmp_path):
    first, second = lens("Lens A", FINE), lens("Lens A", FINE, mount="Other")
    third = lens("Lens A", FINE, mount="Third")
    before = {"a.xml": xml(first), "b.xml": xml(second)}
    after = {"a.xml": xml(first), "b.xml": xml(second), "c.xml": xml(third)}
    result = compare(tmp_path, before, after)
    assert new(result) == [("duplicate-lens", "c.xml", 2)]


def test_fixing_one_of_two_folding_entries_resolves_one(tmp_path):
    before = xml(lens("Lens A", FOLDING, FOLDING_TOO))
    after = xml(lens("Lens A", FOLDING, FOLDING_TOO.replace("-0.25", "0.01")))
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert new(result) == [] and result.resolved == 1


def test_a_broken_file_of_a_directory_baseline_makes_no_finding_in_it_new(tmp_path):
    good = xml(lens("Lens B", FOLDING))
    broken = good.replace("</maker>", "</makr>")
    result = compare(tmp_path, {"a.xml": broken}, {"a.xml": good})
    assert not result.failed
    assert [(f.code, f.known) for f in result.findings] == [
        ("baseline-unreadable", False),
        ("fold-in-image", True),
    ]
    assert "not counted as new" in result.findings[0].message


def test_a_broken_baseline_file_makes_findings_in_other_files_no_less_new(tmp_path):
    broken = xml(lens("Lens B", FINE)).replace("</maker>", "</makr>")
    before = {"a.xml": broken, "b.xml": xml(lens("Lens Z", FINE))}
    after = {"a.xml": broken, "b.xml": xml(lens("Lens Z", FINE, FOLDING))}
    result = compare(tmp_path, before, after)
    assert [(f.code, Path(f.file).name, f.known) for f in result.findings] == [
        ("xml-error", "a.xml", True),
        ("fold-in-image", "b.xml", False),
    ]


# -- identical duplicates are warnings --------------------------------------------------


def test_two_entries_for_one_focal_with_the_same_values_are_a_warning(tmp_path):
    text = xml(lens("Lens A", FINE, FINE.replace("k1=", " k1=").replace("0.01", "0.010")))
    (tmp_path / "a.xml").write_text(text)
    [finding] = check(tmp_path / "a.xml").findings
    assert (finding.severity, finding.code) == ("warning", "duplicate-focal")
    assert f"identical to the one at line {line_of(text, 'focal')}" in finding.message


def test_two_different_entries_for_one_focal_are_an_error(tmp_path):
    (tmp_path / "a.xml").write_text(xml(lens("Lens A", FINE, FINE.replace("0.01", "0.02"))))
    [finding] = check(tmp_path / "a.xml").findings
    assert (finding.severity, finding.code) == ("error", "duplicate-focal")


def test_two_identical_lens_definitions_are_a_warning(tmp_path):
    (tmp_path / "a.xml").write_text(xml(lens("Lens A", FINE), lens("LENS  A", FINE)))
    [finding] = check(tmp_path / "a.xml").findings
    assert (finding.severity, finding.code) == ("warning", "duplicate-lens")
    assert not check(tmp_path / "a.xml").failed


def test_lens_definitions_that_differ_in_a_comment_only_are_identical(tmp_path):
    commented = lens("Lens A", FINE).replace("<calibration>", "<calibration><!-- by me -->")
    (tmp_path / "a.xml").write_text(xml(lens("Lens A", FINE), commented))
    assert [f.severity for f in check(tmp_path / "a.xml").findings] == ["warning"]


@pytest.mark.parametrize(
    "first, second, severity",
    [
        # Numbers compare as numbers: the same value written otherwise is the same.
        ('k1="-0.5" k2="0"', 'k1="-0.50" k2="-0"', "warning"),
        ('k1="-0.5"', 'k1="-0.5" k2="0" k3="0.0"', "warning"),  # omitted: the default
        ('k1="-0.5"', 'k1="-0.5" k2="1e-300"', "error"),
        ('k1="-0.5"', None, "error"),  # one calibrates vignetting, the other does not
    ],
)
def test_lens_definitions_are_identical_when_their_values_are(tmp_path, first, second, severity):
    def with_vignetting(attributes):
        if attributes is None:
            return lens("Lens A", FINE)
        row = f'<vignetting model="pa" focal="10" aperture="2.8" distance="10" {attributes}/>'
        return lens("Lens A", FINE).replace("</calibration>", row + "</calibration>")

    (tmp_path / "a.xml").write_text(xml(with_vignetting(first), with_vignetting(second)))
    found = [(f.severity, f.code) for f in check(tmp_path / "a.xml").findings]
    assert (severity, "duplicate-lens") in found


def test_two_lens_definitions_with_different_entries_are_an_error(tmp_path):
    (tmp_path / "a.xml").write_text(xml(lens("Lens A", FINE), lens("Lens A", FOLDING)))
    codes = [(f.severity, f.code) for f in check(tmp_path / "a.xml").findings]
    assert ("error", "duplicate-lens") in codes


def test_a_known_identical_duplicate_that_now_differs_fails(tmp_path):
    before = xml(lens("Lens A", FINE, FINE))
    after = xml(lens("Lens A", FINE, FINE.replace("0.01", "0.02")))
    result = compare(tmp_path, {"a.xml": before}, {"a.xml": after})
    assert [(f.severity, f.known) for f in result.findings] == [("error", False)]
    assert result.failed


def test_a_duplicate_names_the_location_of_what_it_repeats(tmp_path):
    text = xml(lens("Lens A", FINE), lens("Lens A", FOLDING))
    (tmp_path / "a.xml").write_text(text)
    duplicate = next(f for f in check(tmp_path).findings if f.code == "duplicate-lens")
    assert duplicate.related == ((str(tmp_path / "a.xml"), 2),)
    assert duplicate.line == line_of(text, "<lens>", 2)


# -- any reordering, reindenting or renaming keeps every finding known ------------------

LENSES = [
    lens("Lens A", FOLDING, FINE),
    lens("Lens B", FINE, FINE.replace("0.01", "0.02")),  # a duplicate focal
    lens("Lens C", FOLDING_TOO),
    lens("Lens D", FINE),
    lens("Lens D", FOLDING),  # a duplicate lens
    lens("Lens E", '<distortion model="poly3" focal="0" k1="0.1"/>'),  # a bad value
]


def renamed(block: str, style: str) -> str:
    """The lens block with its model name changed only in case or spacing."""

    def change(match: re.Match) -> str:
        name = match.group(1)
        name = {"upper": name.upper(), "lower": name.lower(), "spaced": name.replace(" ", "  ")}[
            style
        ]
        return f"<model>{name}</model>"

    return re.sub(r"<model>(.*?)</model>", change, block)


@settings(max_examples=25, deadline=None)
@given(
    order=st.permutations(range(len(LENSES))),
    split=st.integers(0, len(LENSES)),
    padding=st.lists(st.sampled_from(["", "\n", "  <!-- moved -->\n", "\n\n\n"]), min_size=6),
    style=st.sampled_from(["upper", "lower", "spaced"]),
    renamed_lens=st.integers(0, len(LENSES) - 1),
)
def test_reordering_reindenting_and_renaming_lenses_introduces_no_finding(
    tmp_path_factory, order, split, padding, style, renamed_lens
):
    # The baseline: all lenses in one file. The change: reordered, split over
    # two files, blank lines and comments between them, one renamed in case or
    # spacing only (so that a duplicate lens stays a duplicate).
    blocks = [renamed(LENSES[i], style) if i == renamed_lens else LENSES[i] for i in order]
    blocks = [padding[i % len(padding)] + block for i, block in enumerate(blocks)]
    before = {"a.xml": xml(*LENSES)}
    after = {"a.xml": xml(*blocks[:split]), "b.xml": xml(*blocks[split:])}
    directory = tmp_path_factory.mktemp("reordered")
    baseline, changed = databases(directory, before, after)
    expected = check(baseline)
    result = check(changed, baseline=baseline)
    assert new(result) == []
    assert len(result.findings) == len(expected.findings)
    assert not result.failed and result.resolved == 0
