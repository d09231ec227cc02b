"""scripts/recall.py: what the maintainers corrected, and what check flagged
at the parent revision, counted on a hand-made history."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import git_commit

ROOT = Path(__file__).resolve().parents[1]

pytestmark = pytest.mark.skipif(
    subprocess.run(["git", "--version"], capture_output=True).returncode != 0,
    reason="git is not installed",
)


def load_recall():
    spec = importlib.util.spec_from_file_location("recall", ROOT / "scripts" / "recall.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("recall", module)
    spec.loader.exec_module(module)
    return module


recall = load_recall()

FOLDING = '<distortion model="poly3" focal="16" k1="-0.11"/>'  # folds inside its image
FIXED = '<distortion model="poly3" focal="16" k1="-0.01"/>'
TCA = '<tca model="poly3" focal="16" vr="1.0002" vb="0.9998"/>'
TCA_CHANGED = '<tca model="poly3" focal="16" vr="1.0003" vb="0.9998"/>'


def vignetting(aperture: str) -> str:
    return (
        f'<vignetting model="pa" focal="16" aperture="{aperture}" distance="10" '
        f'k1="-0.1" k2="0" k3="0"/>'
    )


def text(name: str, *elements: str, broken: bool = False) -> str:
    body = "\n".join(f"      {e}" for e in elements)
    end = "" if broken else "</lensdatabase>\n"
    return (
        '<lensdatabase version="2">\n  <lens>\n'
        f"    <maker>Test</maker>\n    <model>{name}</model>\n"
        "    <mount>Test</mount>\n    <cropfactor>1.5</cropfactor>\n"
        f"    <calibration>\n{body}\n    </calibration>\n  </lens>\n{end}"
    )


def commit(repository: Path, content: str, message: str) -> None:
    git_commit(repository, {"data/db/db.xml": content}, message)


@pytest.fixture
def history(tmp_path) -> Path:
    repository = tmp_path / "lensfun"
    repository.mkdir()
    subprocess.run(["git", "-C", str(repository), "init", "-q"], check=True)
    distortion = ['<distortion model="poly3" focal="24" k1="-0.01"/>']
    start = (FOLDING, *distortion, TCA, vignetting("2.8"), vignetting("4"))
    commit(repository, text("Zoom", *start), "start: 5 elements, the fold flagged")
    after_fix = (FIXED, *distortion, TCA, vignetting("2.8"), vignetting("4"))
    commit(repository, text("Zoom", *after_fix), "corrects the fold")
    commit(repository, text("Zoom", FIXED, *distortion, TCA, vignetting("2.8")), "removes one")
    renamed = (FIXED, *distortion, TCA, vignetting("2.8"))
    commit(repository, text("Zoom II", *renamed), "renames the lens: corrects nothing")
    commit(repository, text("Zoom II", FIXED, *distortion, TCA_CHANGED, vignetting("2.8")), "tca")
    changed = (FIXED, *distortion, TCA_CHANGED, vignetting("2.8"))
    commit(repository, text("Zoom II", *changed, broken=True), "breaks the file")
    commit(repository, text("Zoom II", *changed), "repairs it")
    return repository


def test_recall_counts_a_hand_made_history(history):
    measured = recall.measure(history)
    kinds = measured["kind"]
    # Corrected: the fold (flagged at its parent by fold-in-image), a vignetting
    # entry removed, a TCA entry changed; the rename, the breaking and the
    # repair correct nothing.
    assert [(kinds[k].corrected, kinds[k].flagged) for k in recall.KINDS] == [(1, 1), (1, 0),
                                                                              (1, 0)]  # fmt: skip
    assert (kinds["all"].corrected, kinds["all"].flagged) == (3, 1)
    # The three parents hold 5, 5 and 4 elements; one of them is flagged.
    assert (kinds["all"].elements, kinds["all"].elements_flagged) == (14, 1)
    assert (kinds["distortion"].elements, kinds["distortion"].elements_flagged) == (6, 1)
    assert measured["code"]["fold-in-image"].flagged == 1
    assert measured["events"]["events"] == 3 and measured["events"]["flagged"] == 1


def test_a_duplicate_lens_flags_every_element_of_its_lens(tmp_path):
    repository = tmp_path / "lensfun"
    repository.mkdir()
    subprocess.run(["git", "-C", str(repository), "init", "-q"], check=True)
    one = text("Zoom", FIXED, TCA).replace("</lensdatabase>\n", "")
    twice = one + one.split('<lensdatabase version="2">\n', 1)[1].replace("-0.01", "-0.02")
    commit(repository, twice + "</lensdatabase>\n", "the lens twice, with two 16 mm entries")
    commit(repository, one + "</lensdatabase>\n", "removes the second")
    measured = recall.measure(repository)
    # The second lens's distortion and TCA: removed; both flagged by duplicate-lens.
    assert (measured["kind"]["all"].corrected, measured["kind"]["all"].flagged) == (2, 2)
    assert measured["code"]["duplicate-lens"].flagged == 2


def test_the_table_names_recall_and_the_base_rate(history):
    output = recall.table(recall.measure(history))
    assert "recall" in output and "base rate" in output
    assert "correction events: 3, with a flagged element: 1 (33.3%)" in output
