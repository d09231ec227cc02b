"""`lensaudit history`: a lens renamed, or its crop factor corrected, keeps the
commit that introduced its calibrations (issue 24, item 8); a calibration
copied to a new lens while the old one stays is the copy's own."""

from __future__ import annotations

import shutil

import pytest

from lensaudit.history import audit_history
from test_history import _git

FOLDING = '<distortion model="poly3" focal="16" k1="-0.11"/>'
OTHER = '<distortion model="poly3" focal="24" k1="-0.02"/>'  # r_max finite, no fold


def lens(model: str, crop: str = "1", *entries: str) -> str:
    rows = "".join(f"      {e}\n" for e in entries or (FOLDING, OTHER))
    return (
        f"  <lens>\n    <maker>Acme</maker>\n    <model>{model}</model>\n"
        f"    <mount>Test</mount>\n    <cropfactor>{crop}</cropfactor>\n"
        f"    <calibration>\n{rows}    </calibration>\n  </lens>\n"
    )


@pytest.fixture(scope="module")
def history(tmp_path_factory):
    """(result, {label: hash}): add (c1), rename (c2), correct the crop factor
    (c3), copy the calibration to a second lens (c4), then recalibrate the
    renamed lens at 16 mm (c5) and rename it back (c6)."""
    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    path = tmp_path_factory.mktemp("renames")
    _git(path, "init", "-q", "-b", "main")
    (path / "data" / "db").mkdir(parents=True)
    commits = {}
    steps = [
        ("c1", lens("Acme 16-24mm")),
        ("c2", lens("Acme 16-24mm f/4")),
        ("c3", lens("Acme 16-24mm f/4", "1.5")),
        ("c4", lens("Acme 16-24mm f/4", "1.5") + lens("Acme 16-24mm f/4 II", "1.5")),
        (
            "c5",
            lens("Acme 16-24mm f/4", "1.5", FOLDING.replace("-0.11", "-0.12"), OTHER)
            + lens("Acme 16-24mm f/4 II", "1.5"),
        ),  # fmt: skip
        (
            "c6",
            lens("Acme 16-24mm", "1.5", FOLDING.replace("-0.11", "-0.12"), OTHER)
            + lens("Acme 16-24mm f/4 II", "1.5"),
        ),  # fmt: skip
    ]
    for day, (label, lenses) in enumerate(steps, start=1):
        text = f'<lensdatabase version="2">\n{lenses}</lensdatabase>\n'
        (path / "data" / "db" / "a.xml").write_text(text)
        _git(path, "add", "-A")
        date = f"2020-02-{day:02d}T12:00:00+00:00"
        _git(path, "commit", "-q", "-m", label, date=date)
        commits[_git(path, "rev-parse", "HEAD")] = label
    return audit_history(path), commits


def test_renames_and_crop_corrections_keep_the_calibrations_introducer(history):
    result, labels = history
    found = {(i.entry.lens, i.entry.focal): labels[i.commit.hash] for i in result.introduced}
    assert found == {
        ("Acme 16-24mm", 16.0): "c5",  # recalibrated by c5; renamed back by c6
        ("Acme 16-24mm", 24.0): "c1",  # through two renames and a crop factor
        ("Acme 16-24mm f/4 II", 16.0): "c4",  # copied while the original stayed
        ("Acme 16-24mm f/4 II", 24.0): "c4",
    }


def test_the_lensfun_history_dates_its_entries_as_docs_history_md_says(lensfun_head_history):
    """docs/history.md quotes these counts, at the bundle's master."""
    result = lensfun_head_history
    by_commit: dict[str, int] = {}
    by_day: dict[str, int] = {}
    for entry in result.introduced:
        if entry.commit is not None:
            by_commit[entry.commit.hash[:7]] = by_commit.get(entry.commit.hash[:7], 0) + 1
            day = str(entry.commit.date)[:10]
            by_day[day] = by_day.get(day, 0) + 1
    assert len(result.introduced) == 1988
    assert by_day["2014-04-03"] == 143
    assert (by_commit["faa48ea"], by_commit["1dbb9a7"]) == (196, 361)
