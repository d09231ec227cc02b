"""`lensaudit check --cache` reads files through the reader's one cache
(`lensaudit.read.Cache`): the output never changes because of it, a file is
parsed again when its bytes change whatever its size and time, the same
bytes in the database and its baseline are parsed once, and a damaged or
unusable cache changes nothing."""

from __future__ import annotations

import io
import os
import shutil
import subprocess
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings

from conftest import GIT_ENVIRONMENT, lens_xml
from damage import FLIPS, flipped
from lensaudit.check import check
from lensaudit.check_formats import writer
from lensaudit.cli import main

FOLDING = '<distortion model="poly3" focal="10" k1="-0.3"/>'  # folds inside its image
NEAR = '<distortion model="poly3" focal="20" k1="-0.05"/>'  # folds just outside
OUTSIDE = '<distortion model="poly3" focal="30" k1="-0.03"/>'  # folds further out
SECOND_FOCAL = '<distortion model="poly3" focal="10" k1="-0.2"/>'  # a second 10 mm entry
BAD_VALUE = '<distortion model="poly3" focal="40" k1="x"/>'
UNKNOWN_MODEL = '<distortion model="acm" focal="50" k1="0.1"/>'
VIGNETTING = (
    '<vignetting model="pa" focal="10" aperture="2.8" distance="10" k1="-2" k2="0" k3="0"/>'
)


def records() -> list[Path]:
    """The reader's cache records."""
    return sorted(Path(os.environ["LENSAUDIT_CACHE_DIR"]).glob("files/*.rec"))


@pytest.fixture
def bad_database(tmp_path: Path) -> Path:
    """A database with a fold, duplicates, bad entries and three files that cannot be used."""
    database = tmp_path / "db"
    database.mkdir()
    entries = (FOLDING, NEAR, OUTSIDE, SECOND_FOCAL, BAD_VALUE, UNKNOWN_MODEL, VIGNETTING)
    (database / "good.xml").write_text(lens_xml(*entries))
    # The same lens again, with other entries: a duplicate lens across files.
    (database / "copy.xml").write_text(lens_xml(NEAR))
    whole = lens_xml(FOLDING).encode()
    (database / "broken.xml").write_bytes(whole[: len(whole) // 2])
    (database / "foreign.xml").write_bytes(b"<html><distortion model='poly3' focal='1'/></html>")
    os.mkfifo(database / "pipe.xml")
    return database


def invoke(*arguments: str) -> tuple[int, str]:
    result = CliRunner().invoke(main, ["check", *arguments])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.output
    return result.exit_code, result.output


def cold_warm_and_uncached(*arguments: str) -> list[tuple[int, str]]:
    """The same check with an empty cache, again with what it stored, and without a cache."""
    shutil.rmtree(os.environ["LENSAUDIT_CACHE_DIR"], ignore_errors=True)
    cold = invoke(*arguments)
    assert records()
    return [cold, invoke(*arguments), invoke(*arguments, "--no-cache")]


def rendered(path: Path, **options) -> str:
    """The JSON output of a library check of ``path``."""
    stream = io.StringIO()
    writer("json")(check(path, **options), stream)
    return stream.getvalue()


@pytest.fixture
def parses(monkeypatch) -> list[int]:
    """The number of bytes of each file the reader parses, in this process."""
    from lensaudit.read import parallel, xml

    parsed: list[int] = []
    real = xml.parse

    def counting(data: bytes, *arguments, **options):
        parsed.append(len(data))
        return real(data, *arguments, **options)

    monkeypatch.setattr(xml, "parse", counting)
    monkeypatch.setattr(parallel, "cpus", lambda: 1)  # parsed here, where it counts
    return parsed


@pytest.mark.parametrize("output_format", ["text", "json"])
def test_a_warm_check_of_the_bundled_database_prints_what_a_cold_one_does(
    bundled_db, output_format
):
    cold, warm, uncached = cold_warm_and_uncached(str(bundled_db), "-f", output_format)
    assert cold[0] == 1  # the bundled database has folds inside the image
    assert warm == cold == uncached


@pytest.mark.parametrize("output_format", ["text", "json"])
@pytest.mark.parametrize("options", [(), ("--verbose",), ("--margin", "1.5")])
def test_a_warm_check_of_bad_input_prints_what_a_cold_one_does(
    bad_database, output_format, options
):
    cold, warm, uncached = cold_warm_and_uncached(str(bad_database), "-f", output_format, *options)
    for code in (
        "xml-error",
        "not-a-database",
        "unreadable",
        "duplicate-lens",
        "duplicate-focal",
        "bad-value",
        "unknown-model",
        "fold-in-image",
        "vignetting-zero-in-image",
    ):
        assert code in cold[1]
    assert warm == cold == uncached


def test_a_warm_check_against_a_directory_baseline_prints_what_a_cold_one_does(
    bad_database, tmp_path
):
    baseline = tmp_path / "before"
    baseline.mkdir()
    for file in bad_database.iterdir():
        if file.is_file():
            (baseline / file.name).write_bytes(file.read_bytes())
    (baseline / "good.xml").write_text(lens_xml(NEAR, OUTSIDE))  # the fold is new
    cold, warm, uncached = cold_warm_and_uncached(
        str(bad_database), "-f", "json", "--baseline", str(baseline)
    )
    assert '"known": true' in cold[1] and '"known": false' in cold[1]
    assert warm == cold == uncached


@pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")
def test_a_warm_check_against_a_git_baseline_prints_what_a_cold_one_does(tmp_path, bundled_db):
    repository = tmp_path / "repo"
    database = repository / "db"
    database.mkdir(parents=True)
    for name in ("6x6.xml", "actioncams.xml", "slr-tokina.xml"):
        (database / name).write_bytes((bundled_db / name).read_bytes())

    def git(*arguments: str) -> None:
        subprocess.run(
            ["git", *arguments],
            cwd=repository,
            check=True,
            capture_output=True,
            env={**os.environ, **GIT_ENVIRONMENT},
        )

    git("init", "-q")
    git("add", "db")
    git("commit", "-q", "-m", "database")
    changed = database / "actioncams.xml"
    text = changed.read_text()
    first = text.index("<distortion")
    changed.write_text(text[:first] + FOLDING + "\n" + text[first:])
    for output_format in ("text", "json"):
        cold, warm, uncached = cold_warm_and_uncached(
            str(database), "-f", output_format, "--baseline", "HEAD"
        )
        assert cold[0] == 1
        assert warm == cold == uncached


def test_a_warm_check_parses_no_file(bad_database, parses):
    check(bad_database, cache=True)
    # Every file that could be read: the FIFO cannot.
    assert sorted(parses) == sorted(f.stat().st_size for f in bad_database.iterdir() if f.is_file())
    parses.clear()
    check(bad_database, cache=True)
    assert parses == []


def test_the_same_bytes_in_the_baseline_are_parsed_once(bad_database, tmp_path, parses):
    baseline = tmp_path / "before"
    shutil.copytree(bad_database, baseline, ignore=lambda _, names: ["pipe.xml"])
    (baseline / "copy.xml").write_text(lens_xml(OUTSIDE))  # the only file that differs
    check(bad_database, baseline=baseline, cache=True)
    sizes = [f.stat().st_size for f in bad_database.iterdir() if f.is_file()]
    assert sorted(parses) == sorted([*sizes, (baseline / "copy.xml").stat().st_size])


def test_a_file_changed_within_the_same_size_and_time_is_parsed_again(bad_database):
    path = bad_database / "good.xml"
    before = invoke(str(bad_database), "-f", "json")
    status = path.stat()
    text = path.read_text()
    assert 'k1="-0.3"' in text
    path.write_text(text.replace('k1="-0.3"', 'k1="-0.4"'))  # the same size
    os.utime(path, ns=(status.st_atime_ns, status.st_mtime_ns))
    assert path.stat().st_size == status.st_size
    after = invoke(str(bad_database), "-f", "json")
    assert after != before
    assert after == invoke(str(bad_database), "-f", "json", "--no-cache")


@settings(
    max_examples=10, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(flips=FLIPS)
def test_cache_records_with_flipped_bytes_change_nothing(bad_database, flips):
    expected = rendered(bad_database)
    check(bad_database, cache=True)
    for record in records():
        record.write_bytes(flipped(record.read_bytes(), flips))
    assert rendered(bad_database, cache=True) == expected


def test_an_unusable_cache_directory_changes_nothing(bad_database, tmp_path, monkeypatch):
    expected = invoke(str(bad_database), "-f", "json", "--no-cache")
    in_the_way = tmp_path / "a file"
    in_the_way.write_text("not a directory")
    monkeypatch.setenv("LENSAUDIT_CACHE_DIR", str(in_the_way))
    assert invoke(str(bad_database), "-f", "json") == expected
    assert in_the_way.read_text() == "not a directory"


def test_help_documents_the_cache_option():
    output = CliRunner().invoke(main, ["check", "--help"]).output
    assert "--cache / --no-cache" in output
    assert "not parsed again" in " ".join(output.split())
