"""`lensaudit check` reuses what an earlier check made of the same bytes: the
output never changes because of the cache, a changed file is parsed again
whatever its size and time, a damaged or foreign store file is ignored, and
the check's store file shares the cache directory's bound."""

from __future__ import annotations

import io
import marshal
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import GIT_ENVIRONMENT, lens_xml
from damage import FLIPS, flipped
from lensaudit import cache as scan_cache
from lensaudit import store
from lensaudit.check import cache as check_cache
from lensaudit.check import check, parsing
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


def cache_file() -> Path:
    return Path(os.environ["LENSAUDIT_CACHE_DIR"]) / f"{check_cache.KIND}-{check_cache.NAME}.cache"


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
    assert cache_file().is_file()
    return [cold, invoke(*arguments), invoke(*arguments, "--no-cache")]


def rendered(path: Path, **options) -> str:
    """The JSON output of a library check of ``path``."""
    stream = io.StringIO()
    writer("json")(check(path, **options), stream)
    return stream.getvalue()


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


def test_findings_kept_for_one_margin_do_not_answer_another(bad_database):
    invoke(str(bad_database), "-f", "json")
    assert invoke(str(bad_database), "-f", "json", "--margin", "2") == invoke(
        str(bad_database), "-f", "json", "--margin", "2", "--no-cache"
    )


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


def test_a_warm_check_parses_no_file(bad_database, monkeypatch):
    invoke(str(bad_database))

    def refuse(job):
        raise AssertionError(f"{job.name} parsed again")

    monkeypatch.setattr(parsing, "read_parts", refuse)
    assert invoke(str(bad_database))[0] == 1


def test_the_same_bytes_in_the_baseline_are_parsed_once(bad_database, tmp_path, monkeypatch):
    baseline = tmp_path / "before"
    shutil.copytree(bad_database, baseline, ignore=lambda _, names: ["pipe.xml"])
    parsed = []
    real = parsing.read_parts

    def counting(job):
        parsed.append(job.name)
        return real(job)

    monkeypatch.setattr(parsing, "read_parts", counting)
    monkeypatch.setattr("lensaudit.workers._cpus", lambda: 1)  # parsed here, where it counts
    check(bad_database, baseline=baseline, cache=True)
    readable = [f for f in bad_database.iterdir() if f.is_file()]
    assert sorted(Path(name).name for name in parsed) == sorted(f.name for f in readable)


def test_a_warm_check_imports_no_numpy(bad_database):
    # In fresh processes: this one has imported numpy long ago.
    script = (
        "import sys; from lensaudit.check import check; "
        f"check({str(bad_database)!r}, cache=True); print('numpy' in sys.modules)"
    )
    outputs = [
        subprocess.run(
            [sys.executable, "-c", script], capture_output=True, text=True, check=True
        ).stdout
        for _ in range(2)
    ]
    assert outputs == ["True\n", "False\n"]


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
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(flips=FLIPS)
def test_a_store_file_with_flipped_bytes_is_ignored(bad_database, flips):
    expected = rendered(bad_database)
    check(bad_database, cache=True)
    whole = cache_file().read_bytes()
    cache_file().write_bytes(flipped(whole, flips))
    assert rendered(bad_database, cache=True) == expected


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(fraction=st.floats(0, 1, exclude_max=True))
def test_a_truncated_store_file_is_ignored(bad_database, fraction):
    expected = rendered(bad_database)
    check(bad_database, cache=True)
    whole = cache_file().read_bytes()
    cache_file().write_bytes(whole[: int(len(whole) * fraction)])
    assert rendered(bad_database, cache=True) == expected


def test_a_store_file_of_another_fingerprint_is_ignored(bad_database, monkeypatch):
    expected = rendered(bad_database)
    monkeypatch.setattr(check_cache, "fingerprint", lambda: b"another version")
    check(bad_database, cache=True)
    # Rows of another version, had they been used: nothing in any file.
    records = marshal.loads(cache_file().read_bytes()[len(store.MAGIC) + store.CHECKSUM_SIZE :])
    for record in records.values():
        record[1] = marshal.dumps(("", [], None, [], [], []))
        record[2] = {}
    scan_cache.record_file(check_cache.KIND, check_cache.NAME, b"another version").write(records)
    monkeypatch.undo()
    assert rendered(bad_database, cache=True) == expected


@pytest.mark.parametrize(
    "record",
    [
        ["not a summary", b"", {}],
        [(1, None, [("line", "maker", "model", 1.0)]), b"", {}],
        [(0, ("xml-error", 1), []), b"", {}],
        [(0, None, []), "not bytes", {}],
    ],
)
def test_a_record_of_another_shape_is_not_used(bad_database, record):
    expected = rendered(bad_database)
    check(bad_database, cache=True)
    cache = check_cache.CheckCache()
    digests = list(cache._records)
    scan_cache.record_file(check_cache.KIND, check_cache.NAME, check_cache.fingerprint()).write(
        dict.fromkeys(digests, record)
    )
    assert check_cache.CheckCache()._records == {}
    assert rendered(bad_database, cache=True) == expected


@pytest.mark.parametrize(
    "finding",
    [
        ("too", "short"),
        ("error", "fold-in-image", "11", 0, "text", (), (), ()),  # a line that is text
        ("error", "fold-in-image", 11, 0, "text", (), ("a",), ()),  # a related line too
    ],
)
def test_stored_findings_of_another_shape_are_worked_out_again(bad_database, finding):
    expected = rendered(bad_database)
    check(bad_database, cache=True)
    cache = check_cache.CheckCache()
    for record in cache._records.values():
        record[2] = {setting: [finding] for setting in record[2]}
    cache._changed = True
    cache._used = dict.fromkeys(cache._records)
    cache.save()
    assert rendered(bad_database, cache=True) == expected


def test_an_unusable_cache_directory_changes_nothing(bad_database, tmp_path, monkeypatch):
    expected = invoke(str(bad_database), "-f", "json", "--no-cache")
    in_the_way = tmp_path / "a file"
    in_the_way.write_text("not a directory")
    monkeypatch.setenv("LENSAUDIT_CACHE_DIR", str(in_the_way))
    assert invoke(str(bad_database), "-f", "json") == expected
    assert in_the_way.read_text() == "not a directory"


def test_the_check_store_file_is_evicted_with_the_others(bad_database):
    check(bad_database, cache=True)
    old = cache_file().stat().st_mtime - 100
    os.utime(cache_file(), (old, old))
    directory = cache_file().parent
    for index in range(scan_cache.MAX_CACHE_FILES):
        scan_cache.record_file("parsed", f"n{index}", b"format", directory).write(index)
    assert not cache_file().exists()
    assert len(list(directory.glob("*.cache"))) == scan_cache.MAX_CACHE_FILES


def test_writing_the_check_store_file_evicts_the_least_recently_used(bad_database):
    directory = cache_file().parent
    for index in range(scan_cache.MAX_CACHE_FILES):
        file = scan_cache.record_file("parsed", f"n{index}", b"format", directory)
        file.write(index)
        os.utime(file.path, (1000 + index, 1000 + index))
    check(bad_database, cache=True)
    names = sorted(p.name for p in directory.glob("*.cache"))
    assert len(names) == scan_cache.MAX_CACHE_FILES
    assert cache_file().name in names and "parsed-n0.cache" not in names


def test_records_of_earlier_runs_are_kept_only_within_the_bound(tmp_path, monkeypatch):
    first, second = tmp_path / "first.xml", tmp_path / "second.xml"
    first.write_text(lens_xml(FOLDING))
    second.write_text(lens_xml(NEAR))
    check(first, cache=True)
    check(second, cache=True)
    assert len(check_cache.CheckCache()._records) == 2  # both kept: well within the bound
    monkeypatch.setattr(check_cache, "KEEP_BYTES", 0)
    third = tmp_path / "third.xml"
    third.write_text(lens_xml(OUTSIDE))
    check(third, cache=True)
    kept = check_cache.CheckCache()._records
    assert len(kept) == 1
    assert check_cache.CheckCache().file(scan_cache.content_digest(third.read_bytes()))


def test_help_documents_the_cache_option():
    output = CliRunner().invoke(main, ["check", "--help"]).output
    assert "--cache / --no-cache" in output
