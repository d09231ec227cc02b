"""`lensaudit history`: every revision of a database kept in git, and who introduced each fold.

A small repository is built with a known history: files added, modified,
renamed, reformatted and removed, a branch merged, a revision that is not
well-formed XML and a later fix. Expected counts come from the closed-form
r_max of the models used (see :func:`facts`), never from lensaudit.
"""

from __future__ import annotations

import csv
import io
import math
import os
import re
import shutil
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given, settings

from conftest import FOLDING_LENS, clone_history, git_repository, no_child_left
from damage import FLIPS, flipped
from history_blobs import file_versions, read_alone
from lensaudit import read
from lensaudit.cli import main
from lensaudit.history import (
    COUNT_COLUMNS,
    HISTORY_COLUMNS,
    INTRODUCED_COLUMNS,
    HistoryError,
    audit_history,
    audit_revision,
    entry_identity,
    trend_figure,
)
from lensaudit.history import versions as versions_stage
from lensaudit.pipeline import file_metrics

# The shared data directory beside the project's checkout.
BUNDLE = Path(__file__).resolve().parents[2] / "shared" / "data" / "lensfun-db-history.bundle"

HALF_DIAGONAL_MM = math.hypot(18, 12)
CORNER_3_2 = math.hypot(1.5, 1)  # image corner in Hugin units for the default 3:2 aspect


# ----------------------------------------------------------- the known history


@dataclass(frozen=True)
class Entry:
    """A distortion entry of the synthetic database (crop factor 1, aspect 3:2)."""

    model: str
    focal: float
    coefficients: dict[str, str]

    def xml(self) -> str:
        attributes = " ".join(f'{k}="{v}"' for k, v in self.coefficients.items())
        return f'<distortion model="{self.model}" focal="{self.focal:g}" {attributes}/>'


def facts(entry: Entry) -> tuple[bool, bool, bool]:
    """(finite r_max, folds inside the image, folds in the paper's units), closed form.

    Only the families used here: poly3 with k1 < 0 has r_max^2 = (1-k1)/(-3 k1)
    and D(r_max) = (2/3)(1-k1) r_max; ptlens with b = c = 0 and a < 0 has
    r_max^3 = (1-a)/(-4a) and D(r_max) = (3/4)(1-a) r_max; poly5 with k2 = 0
    and k1 < 0 has r_max^2 = -1/(3 k1) and D(r_max) = (2/3) r_max. Otherwise
    D is increasing: r_max is infinite.
    """
    c = {k: float(v) for k, v in entry.coefficients.items()}
    if entry.model == "poly3" and c["k1"] < 0:
        k1 = c["k1"]
        r_max = math.sqrt((1 - k1) / (-3 * k1))
        d_max = 2 / 3 * (1 - k1) * r_max
    elif entry.model == "ptlens" and c.get("a", 0) < 0 and not c.get("b") and not c.get("c"):
        a = c["a"]
        r_max = ((1 - a) / (-4 * a)) ** (1 / 3)
        d_max = 3 / 4 * (1 - a) * r_max
    elif entry.model == "poly5" and c["k1"] < 0 and not c.get("k2"):
        d_max = 2 / 3 * math.sqrt(-1 / (3 * c["k1"]))
    else:
        return False, False, False
    paper_corner = HALF_DIAGONAL_MM / entry.focal
    return True, d_max / CORNER_3_2 < 1, d_max / paper_corner < 1


# Lens name -> maker; every lens is rectilinear, crop factor 1, 3:2.
MAKERS = {
    "Acme 10-20mm": "Acme",
    "Bolt 10-20mm": "Bolt",
    "Echo 35mm": "Echo",
    "Delta 30mm": "Delta",
}

A10 = Entry("poly3", 10, {"k1": "-0.01"})  # finite, no fold
A10_NEW = Entry("poly3", 10, {"k1": "-0.5"})  # folds in both units
A20 = Entry("poly3", 20, {"k1": "-0.02"})  # finite, no fold
B10 = Entry("ptlens", 10, {"a": "-0.1", "b": "0", "c": "0"})  # folds in both units
B10_REFORMATTED = Entry("ptlens", 10, {"a": "-0.100", "b": "0.0", "c": "0"})
B20 = Entry("ptlens", 20, {"a": "0", "b": "0", "c": "0"})  # identity: infinite
E35 = Entry("poly3", 35, {"k1": "-0.01"})  # finite, no fold
D30 = Entry("poly5", 30, {"k1": "-0.1", "k2": "0"})  # folds only in Hugin units


def db_file(lenses: dict[str, list[Entry]], comment: str = "") -> str:
    blocks = []
    for lens, entries in lenses.items():
        lines = "\n".join(f"            {e.xml()}" for e in entries)
        blocks.append(
            textwrap.dedent("""\
            <lens>
                <maker>{maker}</maker>
                <model>{lens}</model>
                <mount>Test Mount</mount>
                <cropfactor>1</cropfactor>
                <calibration>
            {lines}
                </calibration>
            </lens>""").format(maker=MAKERS[lens], lens=lens, lines=lines)
        )
    body = textwrap.indent("\n".join(blocks), "    ")
    return f'<lensdatabase version="2">{comment}\n{body}\n</lensdatabase>\n'


BROKEN_A = db_file({"Acme 10-20mm": [A10_NEW, A20]}).replace("</lens>", "</lense>")

# The database after each commit: file -> {lens: entries}. None: not a database change.
STATES = {
    "c1": {"a.xml": {"Acme 10-20mm": [A10, A20]}},
    "c2": {
        "a.xml": {"Acme 10-20mm": [A10, A20]},
        "b.xml": {"Bolt 10-20mm": [B10, B20]},
        "e.xml": {"Echo 35mm": [E35]},
    },
    "c3": {
        "a.xml": {"Acme 10-20mm": [A10_NEW, A20]},
        "b.xml": {"Bolt 10-20mm": [B10, B20]},
        "e.xml": {"Echo 35mm": [E35]},
    },
    "c4": {
        "a.xml": {"Acme 10-20mm": [A10_NEW, A20]},
        "c.xml": {"Bolt 10-20mm": [B10, B20]},
        "e.xml": {"Echo 35mm": [E35]},
    },
    "c5": {
        "a.xml": {"Acme 10-20mm": [A10_NEW, A20]},
        "c.xml": {"Bolt 10-20mm": [B10, B20]},
        "e.xml": {"Echo 35mm": [E35]},
        "d.xml": {"Delta 30mm": [D30]},
    },
    "c7": {"a.xml": None, "c.xml": {"Bolt 10-20mm": [B10, B20]}, "e.xml": {"Echo 35mm": [E35]}},
    "c8": {
        "a.xml": {"Acme 10-20mm": [A10_NEW, A20]},
        "c.xml": {"Bolt 10-20mm": [B10, B20]},
        "e.xml": {"Echo 35mm": [E35]},
    },
    "c9": {
        "a.xml": {"Acme 10-20mm": [A10_NEW, A20]},
        "c.xml": {"Bolt 10-20mm": [B10, B20]},
        "e.xml": {"Echo 35mm": [E35]},
        "d.xml": {"Delta 30mm": [D30]},
    },
    "c10": {
        "a.xml": {"Acme 10-20mm": [A10_NEW, A20]},
        "c.xml": {"Bolt 10-20mm": [B10, B20]},
        "d.xml": {"Delta 30mm": [D30]},
    },
    "c11": {
        "a.xml": {"Acme 10-20mm": [A10_NEW, A20]},
        "c.xml": {"Bolt 10-20mm": [B20, B10_REFORMATTED]},
        "d.xml": {"Delta 30mm": [D30]},
    },
}
BROKEN_COMMIT = "c7"
MAINLINE = ["c1", "c2", "c3", "c4", "c7", "c8", "c9", "c10", "c11"]


@dataclass
class Repository:
    path: Path
    commits: dict[str, str]  # label -> hash

    def git(self, *args: str) -> str:
        return _git(self.path, *args)


_GIT_ENV = {
    "GIT_CONFIG_GLOBAL": os.devnull,
    "GIT_CONFIG_NOSYSTEM": "1",
    "GIT_AUTHOR_EMAIL": "test@example.org",
    "GIT_COMMITTER_EMAIL": "test@example.org",
    "GIT_COMMITTER_NAME": "Committer",
    "GIT_OPTIONAL_LOCKS": "0",
}


def _git(path: Path, *args: str, author: str = "Tester", date: str = "") -> str:
    env = dict(os.environ, **_GIT_ENV, GIT_AUTHOR_NAME=author)
    if date:
        env.update(GIT_AUTHOR_DATE=date, GIT_COMMITTER_DATE=date)
    done = subprocess.run(
        ["git", "-C", str(path), *args], env=env, check=True, capture_output=True, text=True
    )
    return done.stdout.strip()


@pytest.fixture(scope="module")
def repo(tmp_path_factory) -> Repository:
    """The known history (dates 2020-01-NN at noon UTC, one commit a day):

    c1 add a.xml; c2 add b.xml and e.xml; c3 modify A 10mm; c4 rename b.xml
    to c.xml; c5 (branch) add d.xml; c6 change README only; c7 break a.xml;
    c8 fix a.xml (new formatting, same entries); c9 merge the branch (no
    fast-forward); c10 remove e.xml; c11 reorder and reformat c.xml.
    """
    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    path = tmp_path_factory.mktemp("history-repo")
    _git(path, "init", "-q", "-b", "main")
    db = path / "data" / "db"
    db.mkdir(parents=True)
    commits = {}

    def commit(label: str, message: str, author: str, day: int) -> None:
        date = f"2020-01-{day:02d}T12:00:00+00:00"
        _git(path, "add", "-A")
        _git(path, "commit", "-q", "-m", message, author=author, date=date)
        commits[label] = _git(path, "rev-parse", "HEAD")

    def write(name: str, lenses: dict[str, list[Entry]], comment: str = "") -> None:
        (db / name).write_text(db_file(lenses, comment), encoding="utf-8")

    (db / "lensfun-database.dtd").write_text("<!-- not a database file -->\n")
    write("a.xml", STATES["c1"]["a.xml"])
    commit("c1", "Add a.xml", "Alice", 1)
    write("b.xml", STATES["c2"]["b.xml"])
    write("e.xml", STATES["c2"]["e.xml"])
    commit("c2", "Add b.xml and e.xml", "Bob", 2)
    write("a.xml", STATES["c3"]["a.xml"])
    commit("c3", "Recalibrate Acme at 10 mm", "Carol", 3)
    _git(path, "mv", "data/db/b.xml", "data/db/c.xml")
    commit("c4", "Rename b.xml to c.xml", "Bob", 4)
    _git(path, "checkout", "-q", "-b", "feature")
    write("d.xml", STATES["c5"]["d.xml"])
    commit("c5", "Add Delta on a branch", "Dave", 5)
    _git(path, "checkout", "-q", "main")
    (path / "README").write_text("not the database\n")
    commit("c6", "Add a README", "Alice", 6)
    (db / "a.xml").write_text(BROKEN_A, encoding="utf-8")
    commit("c7", "Break a.xml", "Alice", 7)
    write("a.xml", STATES["c8"]["a.xml"], comment="<!-- repaired -->")
    commit("c8", "Repair a.xml", "Carol", 8)
    _git(
        path,
        "merge",
        "-q",
        "--no-ff",
        "-m",
        "Merge branch feature",
        "feature",
        author="Erin",
        date="2020-01-09T12:00:00+00:00",
    )
    commits["c9"] = _git(path, "rev-parse", "HEAD")
    (db / "e.xml").unlink()
    commit("c10", "Remove e.xml", "Bob", 10)
    write("c.xml", STATES["c11"]["c.xml"])
    commit("c11", "Reorder and reformat c.xml", "Frank", 11)
    return Repository(path, commits)


def expected_counts(state: dict) -> dict[str, int]:
    """Counts of a database state, from :func:`facts` (a broken file counts nothing)."""
    counts = dict.fromkeys(
        (
            "audited",
            "ptlens",
            "poly3",
            "poly5",
            "finite",
            "folds_in_image",
            "folds_in_image_rectilinear",
            "folds_in_image_paper_units_rectilinear",
        ),
        0,
    )
    for lenses in state.values():
        for entries in (lenses or {}).values():
            for entry in entries:
                finite, folds, folds_paper = facts(entry)
                counts["audited"] += 1
                counts[entry.model] += 1
                counts["finite"] += finite
                counts["folds_in_image"] += folds
                counts["folds_in_image_rectilinear"] += folds
                counts["folds_in_image_paper_units_rectilinear"] += folds_paper
    return counts


def label_of(repo: Repository) -> dict[str, str]:
    return {h: label for label, h in repo.commits.items()}


# ------------------------------------------------------------------- counts


def test_the_known_history_exercises_every_case():
    outcomes = {facts(e) for e in (A10, A10_NEW, A20, B10, B20, E35, D30)}
    assert outcomes == {
        (True, False, False),
        (True, True, True),
        (False, False, False),
        (True, True, False),
    }


def test_rows_are_the_commits_that_change_the_database_oldest_first(repo):
    result = audit_history(repo.path)
    labels = [label_of(repo)[r.commit.hash] for r in result.revisions]
    assert labels == ["c1", "c2", "c3", "c4", "c5", "c7", "c8", "c9", "c10", "c11"]
    assert result.commits == 11  # c6 touches only the README
    assert result.newest.hash == repo.commits["c11"]


def test_counts_per_commit_are_exactly_those_of_the_known_states(repo):
    result = audit_history(repo.path)
    for revision in result.revisions:
        label = label_of(repo)[revision.commit.hash]
        expected = expected_counts(STATES[label])
        assert {k: revision.counts[k] for k in expected} == expected, label
        assert revision.files == len(STATES[label])


def test_counts_differ_between_hugin_and_paper_units(repo):
    last = audit_history(repo.path).revisions[-1]
    assert last.counts["folds_in_image"] == 3  # Acme 10 mm, Bolt 10 mm, Delta 30 mm
    assert last.counts["folds_in_image_paper_units_rectilinear"] == 2  # not Delta 30 mm
    assert last.counts["finite"] == 4 and last.share_finite == pytest.approx(4 / 5)


def test_unparsable_revision_counts_nothing_from_that_file_and_says_why(repo):
    result = audit_history(repo.path)
    broken = next(r for r in result.revisions if r.commit.hash == repo.commits[BROKEN_COMMIT])
    assert len(broken.errors) == 1 and broken.errors[0].startswith("a.xml: XML is not well-formed")
    salvaged = len(read.read_bytes(BROKEN_A.encode(), "a.xml").distortion)
    audited_elsewhere = expected_counts(STATES[BROKEN_COMMIT])["audited"]
    assert broken.counts["entries"] == audited_elsewhere + salvaged
    assert broken.record()["not_audited"] == salvaged
    assert broken.record()["files_with_errors"] == 1


def test_merge_and_branch_commits_are_flagged(repo):
    rows = {label_of(repo)[r.commit.hash]: r.record() for r in audit_history(repo.path).revisions}
    assert [label for label, row in rows.items() if row["merge"]] == ["c9"]
    assert [label for label, row in rows.items() if not row["mainline"]] == ["c5"]


def test_first_parent_lists_only_the_main_line(repo):
    result = audit_history(repo.path, first_parent=True)
    labels = [label_of(repo)[r.commit.hash] for r in result.revisions]
    assert labels == MAINLINE
    for label, revision in zip(labels, result.revisions, strict=True):
        expected = expected_counts(STATES[label])
        assert {k: revision.counts[k] for k in expected} == expected, label


# ------------------------------------------------------------- introductions


def introducers(result, repo) -> dict[tuple[str, str, float], str]:
    """(file, lens, focal) -> label of the introducing commit ("" if before the range)."""
    return {
        (i.entry.file, i.entry.lens, i.entry.focal): label_of(repo)[i.commit.hash]
        if i.commit
        else ""
        for i in result.introduced
    }


def test_introducing_commit_of_every_entry_with_finite_r_max(repo):
    assert introducers(audit_history(repo.path), repo) == {
        ("a.xml", "Acme 10-20mm", 10.0): "c3",  # modified by c3; broken by c7, repaired by c8
        ("a.xml", "Acme 10-20mm", 20.0): "c1",  # untouched since c1, through c3, c7, c8
        ("c.xml", "Bolt 10-20mm", 10.0): "c2",  # renamed by c4, reordered by c11
        ("d.xml", "Delta 30mm", 30.0): "c5",  # the branch commit, not the merge
    }


def test_introduced_entries_carry_their_metrics_and_commit(repo):
    result = audit_history(repo.path)
    acme = next(
        i for i in result.introduced if i.entry.lens == "Acme 10-20mm" and i.entry.focal == 10
    )
    assert acme.r_max == pytest.approx(1.0, rel=1e-12)  # sqrt(1.5 / 1.5)
    assert acme.d_max == pytest.approx(1.0, rel=1e-12)  # (2/3)(1.5)
    assert acme.r_normalized == pytest.approx(1 / CORNER_3_2, rel=1e-12)
    assert acme.r_normalized_paper == pytest.approx(10 / HALF_DIAGONAL_MM, rel=1e-12)
    assert acme.folds_in_image
    assert (acme.commit.author, acme.commit.subject) == ("Carol", "Recalibrate Acme at 10 mm")
    assert acme.commit.date == "2020-01-03T12:00:00+00:00"


def test_first_parent_attributes_a_merged_branch_to_its_merge(repo):
    found = introducers(audit_history(repo.path, first_parent=True), repo)
    assert found[("d.xml", "Delta 30mm", 30.0)] == "c9"
    assert found[("a.xml", "Acme 10-20mm", 10.0)] == "c3"


def test_since_leaves_older_coefficients_unattributed(repo):
    result = audit_history(repo.path, since="2020-01-03")
    assert [label_of(repo)[r.commit.hash] for r in result.revisions][0] == "c3"
    assert introducers(result, repo) == {
        ("a.xml", "Acme 10-20mm", 10.0): "c3",
        ("a.xml", "Acme 10-20mm", 20.0): "",
        ("c.xml", "Bolt 10-20mm", 10.0): "",
        ("d.xml", "Delta 30mm", 30.0): "c5",
    }


def test_until_makes_the_newest_revision_that_of_the_day(repo):
    result = audit_history(repo.path, until="2020-01-04")  # the whole day
    assert result.newest.hash == repo.commits["c4"]
    assert introducers(result, repo) == {
        ("a.xml", "Acme 10-20mm", 10.0): "c3",
        ("a.xml", "Acme 10-20mm", 20.0): "c1",
        ("c.xml", "Bolt 10-20mm", 10.0): "c2",
        ("e.xml", "Echo 35mm", 35.0): "c2",
    }


# --------------------------------------------------------- reading and caching


def csv_text(result) -> tuple[str, str]:
    """history.csv and introduced.csv of a result."""
    texts = []
    for write in (result.write_csv, result.write_introduced_csv):
        stream = io.StringIO()
        write(stream)
        texts.append(stream.getvalue())
    return texts[0], texts[1]


def count_reads(monkeypatch) -> list[bytes]:
    """The contents the history hands to the reader, as it reads them (in this
    process: the small repository is read without worker processes); one read
    piece by piece counts where the reader reads it so, else as it is read then."""
    calls: list[bytes] = []
    real_bytes, real_contents, real_pieces = read.read_bytes, read.read_contents, read.read_pieces

    def pieces(data: bytes, *a, **k):
        found = real_pieces(data, *a, **k)
        if found is not None:
            calls.append(data)
        return found

    monkeypatch.setattr(read, "read_pieces", pieces)
    monkeypatch.setattr(
        read, "read_bytes", lambda data, *a, **k: calls.append(data) or real_bytes(data, *a, **k)
    )
    monkeypatch.setattr(
        read,
        "read_contents",
        lambda contents, *a, **k: (
            calls.extend(c[0] for c in contents) or real_contents(contents, *a, **k)
        ),
    )
    return calls


def test_each_distinct_file_version_is_read_once(repo, monkeypatch):
    calls = count_reads(monkeypatch)
    result = audit_history(repo.path)
    objects = [
        line.split(" ", 1) for line in repo.git("rev-list", "--objects", "--all").splitlines()
    ]
    xml_blobs = {
        oid
        for oid, *path in objects
        if path and path[0].startswith("data/db/") and path[0].endswith(".xml")
    }
    # a.xml: c1, c3, broken, repaired; b.xml (renamed as is); c.xml reformatted; d; e.
    assert len(xml_blobs) == 8
    assert len(calls) == len(set(calls)) == len(xml_blobs) == result.blobs == result.blobs_read


def test_file_versions_are_kept_in_the_one_cache_by_content(repo, tmp_path):
    audit_history(repo.path, cache=tmp_path)
    cache = read.Cache(tmp_path)
    kept = []
    for data in [(repo.path / "data" / "db" / n).read_bytes() for n in ("a.xml", "c.xml")]:
        digest = read.cache.content_digest(data)
        kept.append((cache.get(digest, "tables") is not None, cache.get(digest, "metrics")))
    assert all(tables and metrics for tables, metrics in kept)


def count_parses(monkeypatch) -> list[int]:
    """One item for each time the reader's parser runs (in this process): a
    content read piece by piece counts where it is read so."""
    parsed: list[int] = []
    real, real_pieces = read.xml.parse, read.xml.read_pieces

    def pieces(*a, **k):
        found = real_pieces(*a, **k)
        if found is not None:
            parsed.append(1)
        return found

    monkeypatch.setattr(read.xml, "parse", lambda *a, **k: parsed.append(1) or real(*a, **k))
    monkeypatch.setattr(read.xml, "read_pieces", pieces)
    return parsed


def test_the_cache_spares_parsing_and_changes_nothing(repo, tmp_path, monkeypatch):
    first = audit_history(repo.path, cache=tmp_path)
    reads, parses = count_reads(monkeypatch), count_parses(monkeypatch)
    # Another selection of the same commits: not the same run, the same file
    # versions: the newest revision's read from the one cache, the others'
    # summaries taken from the index; none parsed.
    second = audit_history(repo.path, cache=tmp_path, since="2000-01-01")
    assert parses == [] and second.blobs_reused > 0
    assert len(reads) == second.blobs_read == second.blobs - second.blobs_reused
    assert csv_text(second) == csv_text(first)  # as written: NaN never equals itself


def test_the_same_run_again_is_taken_from_the_index_whole(repo, tmp_path, monkeypatch):
    first = audit_history(repo.path, cache=tmp_path)
    calls = count_reads(monkeypatch)
    monkeypatch.setattr(versions_stage, "read_versions", lambda *args: pytest.fail("read"))
    second = audit_history(repo.path, cache=tmp_path)
    assert calls == [] and second.blobs_read == 0 and second.blobs_reused == first.blobs
    assert csv_text(second) == csv_text(first)  # as written: NaN never equals itself
    assert (second.newest, second.commits, second.path) == (first.newest, first.commits, first.path)


def test_the_index_is_one_directory_beside_the_records_of_the_one_cache(repo, tmp_path):
    audit_history(repo.path, cache=tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["files", "history"]
    records = [p.name for p in (tmp_path / "files").iterdir()]
    assert records and all(name.endswith(".rec") for name in records)
    assert sorted(p.name for p in (tmp_path / "history").iterdir()) == ["run", "versions"]


def test_an_index_of_the_earlier_layout_is_replaced(repo, tmp_path):
    (tmp_path / "history").write_bytes(b"lensaudit history index 1\n" + bytes(100))
    first = audit_history(repo.path, cache=tmp_path)
    assert (tmp_path / "history" / "run").is_file() and not first.warnings
    again = audit_history(repo.path, cache=tmp_path)
    assert again.blobs_read == 0 and csv_text(again) == csv_text(first)


def test_a_run_of_another_revision_is_not_taken_from_the_cache(repo, tmp_path):
    audit_history(repo.path, cache=tmp_path)
    older = audit_history(repo.path, revision=repo.commits["c4"], cache=tmp_path)
    alone = audit_history(repo.path, revision=repo.commits["c4"])
    assert older.newest.hash == repo.commits["c4"]
    assert csv_text(older) == csv_text(alone)


def test_the_cache_of_other_code_is_not_used(repo, tmp_path, monkeypatch):
    audit_history(repo.path, cache=tmp_path)
    monkeypatch.setattr(read.cache, "fingerprint", lambda: b"other code 123456")
    parses = count_parses(monkeypatch)
    again = audit_history(repo.path, cache=tmp_path)
    assert again.blobs_reused == 0 and len(parses) == again.blobs_read == again.blobs


def test_an_unusable_cache_directory_is_a_warning_not_an_error(repo, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    result = audit_history(repo.path, cache=blocker)
    assert result.revisions and result.warnings and "not used" in result.warnings[0]


@pytest.mark.parametrize("first", ["full", "shallow"])
def test_a_shallow_clone_and_the_full_repository_at_one_commit_keep_their_own_runs(
    repo, tmp_path, first
):
    shallow = tmp_path / "shallow"
    subprocess.run(
        ["git", "clone", "-q", "--depth", "2", f"file://{repo.path}", str(shallow)], check=True
    )
    paths = {"full": repo.path, "shallow": shallow}
    expected = {name: csv_text(audit_history(path)) for name, path in paths.items()}
    assert expected["full"] != expected["shallow"]  # the clone holds two commits only
    for name in (first, *(set(paths) - {first})):
        assert csv_text(audit_history(paths[name], cache=tmp_path / "cache")) == expected[name]


def test_a_file_name_that_is_not_utf8_is_written_with_backslash_escapes(tmp_path):
    name = os.fsdecode(b"caf\xe9\xff.xml")
    repository = git_repository(tmp_path / "repo", {f"data/db/{name}": FOLDING_LENS})
    written = {}
    for label, path in (("directory", []), ("file", ["--path", f"data/db/{name}"])):
        out = tmp_path / label
        process = subprocess.run(
            [sys.executable, "-m", "lensaudit", "history", str(repository), "-o", str(out)]
            + ["-q", "--no-cache", *path],
            capture_output=True,
            timeout=120,
        )
        assert process.returncode == 0 and process.stderr == b"", process.stderr
        written[label] = (out / "introduced.csv").read_text(encoding="utf-8")
    rows = list(csv.DictReader(io.StringIO(written["directory"])))
    assert [row["file"] for row in rows] == ["caf\\xe9\\xff.xml"]
    assert written["file"] == written["directory"]


def test_a_file_of_someone_else_named_as_the_index_is_kept(repo, tmp_path):
    (tmp_path / "history").write_text("my notes\n")
    result = audit_history(repo.path, cache=tmp_path)
    assert (tmp_path / "history").read_text() == "my notes\n"
    assert len(result.warnings) == 1 and "not used" in result.warnings[0]
    assert csv_text(result) == csv_text(audit_history(repo.path))


@pytest.mark.parametrize("entry", ["run", "versions"])
def test_a_fifo_in_place_of_an_index_entry_is_no_entry(repo, tmp_path, entry):
    audit_history(repo.path, cache=tmp_path)
    (tmp_path / "history" / entry).unlink()
    os.mkfifo(tmp_path / "history" / entry)
    process = subprocess.run(
        [sys.executable, "-m", "lensaudit", "history", str(repo.path), "-q"]
        + ["-o", str(tmp_path / "out"), "--cache-dir", str(tmp_path)],
        capture_output=True,
        timeout=120,  # a FIFO opened to be read blocks until someone writes to it
    )
    assert process.returncode == 0 and process.stderr == b"", process.stderr
    expected = csv_text(audit_history(repo.path))[0]
    assert (tmp_path / "out" / "history.csv").read_text(encoding="utf-8") == expected


@pytest.fixture(scope="module")
def uncached_csv(repo: Repository) -> tuple[str, str]:
    return csv_text(audit_history(repo.path))


@settings(max_examples=25, deadline=None)
@given(flips=FLIPS)
def test_a_damaged_index_gives_the_uncached_history(repo, uncached_csv, tmp_path_factory, flips):
    cache = tmp_path_factory.mktemp("cache")
    audit_history(repo.path, cache=cache)
    changed = False
    for entry in (cache / "history").iterdir():
        original = entry.read_bytes()
        damaged = flipped(original, flips)
        entry.write_bytes(damaged)
        changed |= damaged != original
    if changed:
        again = audit_history(repo.path, cache=cache)
        assert csv_text(again) == uncached_csv


@settings(max_examples=10, deadline=None)
@given(flips=FLIPS)
def test_damaged_records_give_the_uncached_history(repo, uncached_csv, tmp_path_factory, flips):
    cache = tmp_path_factory.mktemp("cache")
    audit_history(repo.path, cache=cache)
    shutil.rmtree(cache / "history")  # the run is made from the records
    records = list(cache.glob("files/*.rec"))
    assert records
    for record in records:
        record.write_bytes(flipped(record.read_bytes(), flips))
    assert csv_text(audit_history(repo.path, cache=cache)) == uncached_csv


def test_a_warm_run_gives_the_history_of_a_cold_one_field_by_field(repo, tmp_path):
    cold = audit_history(repo.path)
    audit_history(repo.path, cache=tmp_path)
    warm = audit_history(repo.path, cache=tmp_path)
    assert warm.blobs_read == 0
    assert warm.revisions == cold.revisions and warm.newest == cold.newest
    # repr: NaN coefficients never equal themselves
    assert repr(warm.introduced) == repr(cold.introduced)


def test_files_of_the_earlier_history_caches_are_removed(repo, tmp_path):
    legacy = [
        tmp_path / "history-0.1.0-0123456789abcdef.sqlite3",
        tmp_path / "history-trend-0a.png",
        tmp_path / "history-blobs.cache",
        tmp_path / "history-run.cache",
        tmp_path / "history-trend.cache",
    ]
    for path in legacy:
        path.write_bytes(b"SQLite format 3\0")
    audit_history(repo.path, cache=tmp_path)
    assert not any(path.exists() for path in legacy)


def test_work_tree_index_and_refs_are_left_as_they_are(repo):
    (repo.path / "data" / "db" / "a.xml").write_text("uncommitted edit\n")
    try:
        index = repo.path / ".git" / "index"
        before = (
            repo.git("status", "--porcelain"),
            repo.git("show-ref"),
            index.stat().st_mtime_ns,
            index.read_bytes(),
        )
        result = audit_history(repo.path)
        after = (
            repo.git("status", "--porcelain"),
            repo.git("show-ref"),
            index.stat().st_mtime_ns,
            index.read_bytes(),
        )
        assert after == before
        assert (repo.path / "data" / "db" / "a.xml").read_text() == "uncommitted edit\n"
        assert result.revisions[-1].counts["audited"] == 5  # the committed a.xml
    finally:
        repo.git("checkout", "-q", "--", "data/db/a.xml")


def test_audit_revision_reads_one_revision_from_scratch(repo):
    audit = audit_revision(repo.path, repo.commits["c4"])
    assert sorted(f.name for f in audit.files) == ["a.xml", "c.xml", "e.xml"]
    assert audit.summary.audited == expected_counts(STATES["c4"])["audited"]


# -------------------------------------------------------------------- errors


def test_a_directory_that_is_not_a_repository_is_refused(tmp_path):
    with pytest.raises(HistoryError, match="not a git repository"):
        audit_history(tmp_path)


def test_a_path_absent_at_every_revision_is_refused(repo):
    with pytest.raises(HistoryError, match="does not exist at any of the 11 commits"):
        audit_history(repo.path, "data/nowhere")


def test_a_path_without_xml_at_any_revision_is_refused(repo):
    with pytest.raises(HistoryError, match="no \\*.xml file at any of the 11 commits"):
        audit_history(repo.path, ".")


@pytest.mark.parametrize("since", ["yesterday", "2020-13-45", "garbage"])
def test_dates_git_would_guess_at_are_refused(repo, since):
    with pytest.raises(HistoryError, match="is not a date"):
        audit_history(repo.path, since=since)


def test_an_empty_date_range_is_refused(repo):
    with pytest.raises(HistoryError, match="no commit"):
        audit_history(repo.path, until="2019-12-31")


# ----------------------------------------------------------------------- CLI


def test_cli_writes_the_five_outputs(repo, tmp_path):
    out = tmp_path / "out"
    result = CliRunner().invoke(
        main, ["history", str(repo.path), "-o", str(out), "--no-cache", "-q"]
    )
    assert result.exit_code == 0, result.output
    assert result.output == ""  # quiet: no progress bar off a terminal, no summary
    assert sorted(p.name for p in out.iterdir()) == [
        "events.csv",
        "history.csv",
        "introduced.csv",
        "trend.png",
        "trend.svg",
    ]
    rows = list(csv.DictReader(io.StringIO((out / "history.csv").read_text())))
    assert tuple(rows[0]) == HISTORY_COLUMNS
    assert [r["commit"] for r in rows][-1] == repo.commits["c11"]
    assert rows[-1]["folds_in_image"] == "3" and rows[-1]["mainline"] == "true"
    introduced = list(csv.DictReader(io.StringIO((out / "introduced.csv").read_text())))
    assert tuple(introduced[0]) == INTRODUCED_COLUMNS
    assert {(r["lens"], r["commit"]) for r in introduced if r["folds_in_image"] == "true"} == {
        ("Acme 10-20mm", repo.commits["c3"]),
        ("Bolt 10-20mm", repo.commits["c2"]),
        ("Delta 30mm", repo.commits["c5"]),
    }
    assert (out / "trend.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<svg" in (out / "trend.svg").read_bytes()[:500]


def test_cli_run_again_writes_the_same_files_without_drawing(repo, tmp_path, monkeypatch):
    from lensaudit.cli import history as cli_history

    cache = tmp_path / "cache"
    args = ["history", str(repo.path), "--cache-dir", str(cache), "-q", "-o"]
    assert CliRunner().invoke(main, [*args, str(tmp_path / "first")]).exit_code == 0
    monkeypatch.setattr(cli_history, "_draw", lambda *a: pytest.fail("drawn again"))
    assert CliRunner().invoke(main, [*args, str(tmp_path / "second")]).exit_code == 0
    for name in ("history.csv", "introduced.csv", "trend.png", "trend.svg"):
        first = (tmp_path / "first" / name).read_bytes()
        assert first and (tmp_path / "second" / name).read_bytes() == first


def test_cli_draws_the_figures_again_when_the_history_changes(repo, tmp_path, monkeypatch):
    from lensaudit.cli import history as cli_history

    cache = tmp_path / "cache"
    args = ["history", str(repo.path), "--cache-dir", str(cache), "-q", "-o", str(tmp_path / "o")]
    assert CliRunner().invoke(main, args).exit_code == 0
    drawn = []
    real = cli_history._draw
    monkeypatch.setattr(cli_history, "_draw", lambda *a: drawn.append(1) or real(*a))
    monkeypatch.setattr(read.parallel, "can_fork", lambda: False)  # drawn here, counted
    older = ["--rev", repo.commits["c4"]]
    assert CliRunner().invoke(main, [*args, *older]).exit_code == 0
    assert drawn == [1]


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no os.fork on this system")
def test_cli_trend_figures_are_drawn_beside_as_here(repo, tmp_path, monkeypatch):
    from lensaudit.cli import history as cli_history

    monkeypatch.setattr(read.parallel, "cpus", lambda: 2)
    args = ["history", str(repo.path), "--no-cache", "-q", "-o"]
    assert CliRunner().invoke(main, [*args, str(tmp_path / "beside")]).exit_code == 0
    with monkeypatch.context() as here:
        here.setattr(read.parallel, "can_fork", lambda: False)
        assert CliRunner().invoke(main, [*args, str(tmp_path / "here")]).exit_code == 0
    png = (tmp_path / "here" / "trend.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "beside" / "trend.png").read_bytes() == png
    # And they are drawn beside: by another process.
    monkeypatch.setattr(
        cli_history, "_draw", lambda *a: dict.fromkeys(cli_history._FIGURES, b"%d" % os.getpid())
    )
    assert CliRunner().invoke(main, [*args, str(tmp_path / "pid")]).exit_code == 0
    drawn_by = (tmp_path / "pid" / "trend.png").read_bytes()
    assert drawn_by.isdigit() and drawn_by != b"%d" % os.getpid()
    assert no_child_left()


def test_cli_summary_names_the_newest_revision(repo, tmp_path):
    result = CliRunner().invoke(
        main,
        ["history", str(repo.path), "-o", str(tmp_path), "--cache-dir", str(tmp_path / "cache")],
    )
    assert result.exit_code == 0, result.output
    assert "11 commits, 10 change the database" in result.output
    assert f"newest {repo.commits['c11'][:7]} 2020-01-11" in result.output
    assert "Auditing" not in result.output  # no progress bar off a terminal


def distinct_file_versions(repo: Repository, *rev_list_args: str) -> int:
    """The XML file versions (blobs) under data/db of the commits git selects."""
    blobs = set()
    for commit in repo.git("rev-list", *rev_list_args, "main").split():
        for line in repo.git("ls-tree", "-r", commit, "--", "data/db").splitlines():
            details, name = line.split("\t", 1)
            if name.endswith(".xml"):
                blobs.add(details.split()[2])
    return len(blobs)


VERSIONS_LINE = re.compile(r"^([\d,]+) file versions: ([\d,]+) read, ([\d,]+) from the last run;")


@pytest.mark.parametrize(
    "runs",
    [
        # Narrower after wider: the case that once printed parts above the whole.
        [[], ["--until", "2020-01-05", "--first-parent"]],
        [["--until", "2020-01-05", "--first-parent"], []],
        [["--first-parent"], [], []],
    ],
    ids=["narrower", "wider", "same again"],
)
def test_cli_file_versions_read_and_from_the_last_run_add_up(repo, tmp_path, runs):
    cache = tmp_path / "cache"
    for number, args in enumerate(runs):
        result = CliRunner().invoke(
            main,
            ["history", str(repo.path), "-o", str(tmp_path / str(number))]
            + ["--cache-dir", str(cache), *args],
        )
        assert result.exit_code == 0, result.output
        found = [VERSIONS_LINE.match(line) for line in result.output.splitlines()]
        [line] = [m for m in found if m]
        total, read_now, reused = (int(group.replace(",", "")) for group in line.groups())
        assert read_now + reused == total, line.group(0)
        rev_list = [a.replace("2020-01-05", "2020-01-05 23:59:59") for a in args]
        assert total == distinct_file_versions(repo, *rev_list)
        if number == 0:
            assert reused == 0  # a cold cache
        if args == runs[number - 1] and number:
            assert read_now == 0  # the same run again: all from the index


@pytest.mark.parametrize(
    "args, message",
    [
        (["--path", "data/nowhere"], "does not exist at any"),
        (["--since", "last week"], "is not a date"),
        (["--rev", "no-such-branch"], "is not a commit"),
    ],
)
def test_cli_bad_input_is_one_line_and_exit_2(repo, tmp_path, args, message):
    result = CliRunner().invoke(
        main, ["history", str(repo.path), "-o", str(tmp_path), "--no-cache", *args]
    )
    assert result.exit_code == 2
    assert message in result.output and "Traceback" not in result.output
    assert len(result.output.strip().splitlines()) == 1


def test_cli_refuses_a_directory_that_is_not_a_repository(tmp_path):
    (tmp_path / "plain").mkdir()
    result = CliRunner().invoke(
        main, ["history", str(tmp_path / "plain"), "-o", str(tmp_path / "out"), "--no-cache"]
    )
    assert result.exit_code == 2
    assert result.output.strip() == f"lensaudit: error: {tmp_path / 'plain'}: not a git repository"


@pytest.mark.parametrize("git_there", ["none", "not executable"])
def test_cli_says_in_one_line_that_git_cannot_be_run(tmp_path, git_there):
    # Not "not a git repository": the repository is one, git is what is missing.
    repository = git_repository(tmp_path / "repo", {"data/db/a.xml": FOLDING_LENS})
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    if git_there == "not executable":
        (bin_dir / "git").write_text("#!/bin/sh\nexit 0\n")
        (bin_dir / "git").chmod(0o644)
    done = subprocess.run(
        [sys.executable, "-m", "lensaudit", "history", str(repository), "-o",
         str(tmp_path / "out"), "--no-cache"],
        capture_output=True,
        text=True,
        env={**os.environ, "PATH": str(bin_dir)},
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    reason = "no git command on PATH" if git_there == "none" else "git: Permission denied"
    assert done.stderr == f"lensaudit: error: cannot run git to read the history: {reason}\n"
    assert done.stdout == ""


def test_trend_figure_marks_the_paper_snapshot(repo):
    import numpy as np
    from matplotlib.dates import date2num

    figure = trend_figure(audit_history(repo.path).to_dataframe())
    top, bottom = figure.axes[:2]
    snapshot = date2num(np.datetime64("2021-05-30"))
    for axes in (top, bottom):
        assert any(
            list(date2num(np.asarray(line.get_xdata()))) == [snapshot, snapshot]
            for line in axes.lines
        )
    labels = [line.get_label() for line in bottom.lines]
    assert any("paper's mixed units" in label for label in labels)
    assert any("Hugin units" in label for label in labels)


def test_trend_figure_takes_history_csv_read_back(repo, tmp_path):
    import pandas

    with open(tmp_path / "history.csv", "w", encoding="utf-8", newline="") as stream:
        audit_history(repo.path).write_csv(stream)
    figure = trend_figure(pandas.read_csv(tmp_path / "history.csv"))
    entries = figure.axes[0].lines[0]
    assert len(entries.get_xdata()) == len(MAINLINE)  # the branch commit c5 is left out
    assert list(entries.get_ydata()) == [expected_counts(STATES[c])["audited"] for c in MAINLINE]


def test_trend_figure_takes_the_records_as_the_dataframe(repo):
    history = audit_history(repo.path)
    from_records = trend_figure(history.records())
    from_frame = trend_figure(history.to_dataframe())
    for mine, theirs in zip(from_records.axes, from_frame.axes, strict=True):
        for line, other in zip(mine.lines, theirs.lines, strict=True):
            assert list(line.get_xdata()) == list(other.get_xdata())
            assert list(line.get_ydata()) == list(other.get_ydata())


def test_the_history_command_draws_its_trend_without_pandas(repo, tmp_path):
    # pandas costs a history run a tenth of a second to import, for nothing.
    # (Drawn in this process, not in one forked beside it, to be seen.)
    script = (
        "import sys\n"
        "from lensaudit.read import parallel\n"
        "parallel.can_fork = lambda: False\n"
        "from lensaudit.console import dispatch\n"
        f"status = dispatch(['history', {str(repo.path)!r}, '-o', {str(tmp_path / 'out')!r}])\n"
        "print(status, 'pandas' in sys.modules, 'matplotlib' in sys.modules)\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    assert done.stdout.split()[-3:] == ["0", "False", "True"]
    assert (tmp_path / "out" / "trend.png").stat().st_size > 0


def test_the_history_command_reads_through_the_one_reader_only(repo, tmp_path):
    script = (
        "import sys\n"
        "from lensaudit.console import dispatch\n"
        f"arguments = ['history', {str(repo.path)!r}, '-q', '-o', {str(tmp_path / 'out')!r}]\n"
        "status = dispatch(arguments)\n"
        "print(status, *sorted(m for m in sys.modules if m.startswith('lensaudit')))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    status, *modules = done.stdout.split()
    assert status == "0" and "lensaudit.read" in modules
    earlier = {"loader", "database", "cache", "store", "workers"}  # the readers before
    assert not {m.split(".")[1] for m in modules if "." in m} & earlier


# --------------------------------------------------- the real Lensfun history


@pytest.fixture(scope="session")
def lensfun_history(tmp_path_factory) -> Path:
    """A clone of the Lensfun database's history, from the shared bundle."""
    return clone_history(tmp_path_factory.mktemp("lensfun-db"), "lensfun-db", "--no-checkout")


def _paper_revision(clone: Path) -> str:
    return _git(clone, "log", "--until=2021-05-30T23:59", "-1", "--format=%H")


def test_the_paper_snapshot_has_the_papers_entry_counts(lensfun_history):
    audit = audit_revision(lensfun_history, _paper_revision(lensfun_history))
    counts = {row.model: row.total for row in audit.summary.rows}
    assert (counts["ptlens"], counts["poly3"], counts["poly5"]) == (4196, 872, 5)


def test_history_up_to_the_paper_snapshot_agrees_with_auditing_it_alone(lensfun_history):
    result = audit_history(lensfun_history, since="2021-05-01", until="2021-05-30")
    assert result.newest.hash == _paper_revision(lensfun_history)
    last = [r for r in result.revisions if r.mainline][-1].counts
    assert (last["ptlens"], last["poly3"], last["poly5"]) == (4196, 872, 5)
    alone = audit_revision(lensfun_history, result.newest.hash).summary
    assert last["finite"] == alone.total.finite
    assert last["folds_in_image"] == len(alone.folding)
    assert last["folds_in_image_paper_units_rectilinear"] == alone.folding_paper_units_rectilinear


def test_introducing_commits_hold_the_entry_and_their_parents_do_not(lensfun_history):
    result = audit_history(lensfun_history, since="2021-01-01", until="2021-05-30")
    dated = [i for i in result.introduced if i.commit is not None]
    assert dated and len(dated) < len(result.introduced)  # the rest predates 2021

    def identities(revision: str) -> set:
        audit = audit_revision(lensfun_history, revision)
        return {entry_identity(e) for e in audit.entries if e.status == "ok"}

    for introduced in dated[:: max(1, len(dated) // 4)][:4]:
        identity = entry_identity(introduced.entry)
        assert identity in identities(introduced.commit.hash)
        for parent in introduced.commit.parents:
            assert identity not in identities(parent)


# ------------------------------------------------- a file version summarized


def test_a_version_summary_counts_what_a_scan_finds(bundled_db):
    from lensaudit.pipeline import run

    for path in sorted(bundled_db.glob("*.xml"))[:12]:
        tables = read.read_bytes(path.read_bytes(), path.name)
        summary = versions_stage.summarize(tables, file_metrics(tables, None))
        found = run(path).summary
        models = {row.model: row for row in found.rows}
        counts = dict(zip(COUNT_COLUMNS, summary.counts, strict=True))
        assert summary.error == tables.error
        assert (counts["entries"], counts["audited"]) == (found.entries, found.audited)
        assert counts["finite"] == found.total.finite
        for model in ("ptlens", "poly3", "poly5"):
            row = models.get(model)
            assert counts[model] == (row.total if row else 0)
            assert counts[f"{model}_finite"] == (row.finite if row else 0)
        assert (
            counts["folds_in_image"],
            counts["folds_in_image_rectilinear"],
            counts["folds_in_image_paper_units_rectilinear"],
        ) == (
            len(found.folding),
            found.folding_rectilinear,
            found.folding_paper_units_rectilinear,
        )
        audited = [e for e in run(path).entries if e.status == "ok"]
        assert summary.identities == [entry_identity(e) for e in audited]


def summaries_by_piece(contents: list[bytes]) -> tuple[int, list[int]]:
    """How many contents the history summarizes piece by piece, and those whose
    summary then differs from the summary of the whole file."""
    pieces, memo, solved = read.Pieces(), {}, {}
    by_pieces, wrong = 0, []
    for number, (data, tables) in enumerate(zip(contents, read_alone(contents), strict=True)):
        whole = versions_stage.summarize(tables, file_metrics(tables, None))
        rows = read.read_pieces(data, pieces)
        if rows is None:
            read.read_bytes(data, "f.xml", pieces=pieces)  # learns its pieces, as the history
            continue
        by_pieces += 1
        parts = versions_stage._piece_parts(rows, memo, solved)
        if versions_stage.Summary("", *versions_stage._added(parts)) != whole:
            wrong.append(number)
    return by_pieces, wrong


def test_real_versions_summarized_by_piece_as_whole(tmp_path):
    by_pieces, wrong = summaries_by_piece(file_versions(tmp_path, revisions=40))
    assert wrong == []
    assert by_pieces > 200


def test_folding_entries_summarized_by_piece_as_whole():
    lens = FOLDING_LENS.split("<lens>", 1)[1].rsplit("</lens>", 1)[0]
    other = lens.replace("Test 10mm", "Other 10mm").replace('k1="-0.11"', 'k1="-0.01"')
    two = lens.replace("Test 10mm", "Two 10mm").replace(
        '<distortion model="poly3" focal="16" k1="-0.11"/>',
        '<distortion model="poly3" focal="12" k1="-0.01"/>'
        '<distortion model="poly3" focal="16" k1="-0.11"/>',
    )
    pieces = [f"<lens>{text}</lens>\n" for text in (lens, other, two, lens)]
    contents = [
        f'<lensdatabase version="2">\n{"".join(order)}</lensdatabase>\n'.encode()
        for order in (pieces, pieces[::-1], pieces[1:], pieces[2:] + pieces[:1])
    ]
    by_pieces, wrong = summaries_by_piece(contents)
    assert (by_pieces, wrong) == (len(contents), [])
    tables = read.read_bytes(contents[0], "f.xml")
    summary = versions_stage.summarize(tables, file_metrics(tables, None))
    assert summary.folding == (0, 3, 4)  # each fold found, at its place


def test_history_in_worker_processes_writes_the_same_files(lensfun_history, tmp_path):
    """The command, a fresh process, reads file versions on every core (forked
    processes); the library gives the same here."""
    since = ["--since", "2019-01-01"]
    command = [sys.executable, "-m", "lensaudit", "history", str(lensfun_history), *since]
    environment = dict(os.environ, LENSAUDIT_CACHE_DIR=str(tmp_path / "cache"))
    subprocess.run(
        [*command, "-o", str(tmp_path / "forked"), "--no-cache", "-q"],
        check=True,
        env=environment,
        capture_output=True,
    )
    result = audit_history(lensfun_history, since="2019-01-01")
    for name, write in (
        ("history.csv", result.write_csv),
        ("introduced.csv", result.write_introduced_csv),
    ):
        stream = io.StringIO()
        write(stream)
        assert (tmp_path / "forked" / name).read_text(encoding="utf-8") == stream.getvalue()


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="no symbolic links here")
def test_the_versions_are_the_files_liblensfun_reads_in_the_database(tmp_path):
    other = FOLDING_LENS.replace("Test 10mm", "Other 10mm")
    repository = git_repository(
        tmp_path / "repo",
        {
            "data/db/a.xml": FOLDING_LENS,
            "data/db/B.XML": other.replace("Other", "Upper"),  # liblensfun: "*.xml" only
            "data/db/notes.txt": other,
            "data/db/sub/c.xml": other.replace("Other", "Sub"),
            "data/db/more.xml/d.xml": other,  # a directory named *.xml is read
        },
    )
    os.symlink("a.xml", repository / "data" / "db" / "link.xml")
    _git(repository, "add", "-A")
    _git(repository, "commit", "-qm", "a link")
    result = audit_history(repository)
    assert result.blobs == 2  # a.xml and more.xml/d.xml, read once each
    lenses = {entry.entry.lens for entry in result.introduced}
    assert lenses == {"Test 10mm", "Other 10mm"}
    assert {entry.entry.file for entry in result.introduced} == {"a.xml", "more.xml/d.xml"}
    # The link changes no database file: its commit is no revision of it.
    assert result.commits == 2 and [r.counts["audited"] for r in result.revisions] == [2]


def test_the_revisions_are_handed_over_as_soon_as_they_are_counted(repo, tmp_path):
    handed = []
    result = audit_history(
        repo.path, cache=tmp_path, revisions_read=lambda *found: handed.append(found)
    )
    assert handed == [(result.newest, result.revisions)] and result.revisions
    assert handed[0][1] is result.revisions  # the result's own, before it is made
    handed.clear()
    again = audit_history(
        repo.path, cache=tmp_path, revisions_read=lambda *found: handed.append(found)
    )
    assert handed == [] and again.revisions == result.revisions  # the run kept whole


def test_progress_reaches_every_file_version_read(repo, tmp_path):
    seen = []
    result = audit_history(
        repo.path, cache=tmp_path, progress=lambda done, total: seen.append((done, total))
    )
    assert seen and seen[-1] == (result.blobs_read, result.blobs_read)
    assert [done for done, _ in seen] == sorted(done for done, _ in seen)
    # Another run of the same versions: all but the newest taken from the index.
    seen.clear()
    again = audit_history(
        repo.path,
        cache=tmp_path,
        since="2000-01-01",
        progress=lambda done, total: seen.append((done, total)),
    )
    assert again.blobs_reused > 0 and seen[-1] == (again.blobs, again.blobs)


# ------------------------------------------------------------------ fold events


def test_events_name_where_a_fold_starts_and_where_it_ends(tmp_path):
    folding = FOLDING_LENS
    fine = folding.replace('k1="-0.11"', 'k1="-0.01"')
    repository = git_repository(tmp_path / "repo", {"data/db/a.xml": folding})
    (repository / "data" / "db" / "a.xml").write_text(fine)
    _git(repository, "commit", "-qam", "fixed")
    result = audit_history(repository)
    events = [(e.commit.subject, e.event, e.identity[1], e.identity[4]) for e in result.events]
    assert events == [
        ("one", "folds", "Test 10mm", 16.0),
        ("fixed", "no-longer-folds", "Test 10mm", 16.0),
    ]
    rows = list(csv.DictReader(io.StringIO(_text(result.write_events_csv))))
    assert [r["event"] for r in rows] == ["folds", "no-longer-folds"] and rows[0]["coefficients"]


def _text(write) -> str:
    stream = io.StringIO()
    write(stream)
    return stream.getvalue()


def test_a_warm_run_keeps_the_events(repo, tmp_path):
    cold = audit_history(repo.path, cache=tmp_path)
    warm = audit_history(repo.path, cache=tmp_path)
    assert warm.blobs_read == 0 and warm.events == cold.events


def test_the_nikkor_z_14_30_folds_from_32aa19d_until_17b336c_fixes_it(lensfun_head_history):
    result = lensfun_head_history
    nikkor = [
        (e.commit.short, e.event, e.branch_commit.short if e.branch_commit else "")
        for e in result.events
        if e.identity[1] == "NIKKOR Z 14-30mm f/4 S" and e.identity[4] == 24.0
    ]
    assert nikkor[:2] == [("32aa19d", "folds", ""), ("79dca3c", "no-longer-folds", "17b336c")]


def test_the_events_of_one_commit_come_in_the_order_of_what_their_entries_are():
    # Identities are numbered in the order they are met, which an index kept from
    # other runs decides: the events of a commit must not follow those numbers.
    from lensaudit.history.audit import BlobAudit
    from lensaudit.history.commits import Commit
    from lensaudit.history.events import fold_events

    kinds = [
        ("Tokina", "Tokina 11-16", 1.0, "ptlens", 11.0, (-0.024, -0.002, 0.005)),
        ("Huawei", "P30 Pro", 4.86, "ptlens", 2.3, (-0.067, 0.084, 0.015)),
        ("Olympus", "M.Zuiko 14-42", 2.0, "poly3", 14.0, (-0.079,)),
    ]
    first = Commit("a" * 40, (), "2020-01-01T00:00:00+00:00", "", "A", "one")
    second = Commit("b" * 40, ("a" * 40,), "2020-01-02T00:00:00+00:00", "", "A", "two")
    found = []
    for numbering in (kinds, kinds[::-1], kinds[1:] + kinds[:1]):
        audits = {
            "empty": BlobAudit("", (), ()),
            "full": BlobAudit("", (), (0, 1, 2), (0, 1, 2)),
        }
        files = {first.hash: {"a.xml": "empty"}, second.hash: {"a.xml": "full"}}
        events = fold_events([first, second], files, audits, numbering)
        found.append([event.identity[0] for event in events])
    assert found == [["Huawei", "Olympus", "Tokina"]] * 3
