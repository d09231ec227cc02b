"""The one cache (lensaudit.read.cache): a warm run prints what a cold one
prints, byte for byte; a record is found by the content of a file, never by
its name, size or time; a damaged or foreign record is ignored and rebuilt
without a word; the records stay within their bounds; and a cache that
cannot be written only costs speed.

Records are looked at as the module documents them: one file per content
digest (BLAKE2b, 16 bytes, of the file's bytes) in ``files`` under the cache
directory, a header and the code's fingerprint, then a marshal table of
named sections, each a (BLAKE2b-16 seal, marshal bytes) pair.
"""

from __future__ import annotations

import hashlib
import marshal
import math
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

import lensaudit.read.cache as cache_module
from conftest import ended_pid, lens_xml
from damage import FLIPS, flipped
from lensaudit import pipeline
from lensaudit.cli import main
from lensaudit.read import Cache, read
from lensaudit.read import xml as xml_module
from lensaudit.read.cache import cache_dir, fingerprint

POLY3 = '<distortion model="poly3" focal="10" k1="{k1}"/>'
FORMATS = ("table", "csv", "json")


def poly3_r_max(k1: float) -> float:
    """r_max of poly3, D(r) = r (1 - k1 + k1 r^2): D'(r) = 0 at r^2 = (k1 - 1) / (3 k1)."""
    return math.sqrt((k1 - 1) / (3 * k1))


@pytest.fixture
def cache_root() -> Path:
    """The cache directory every test is given (see conftest.py)."""
    return Path(os.environ["LENSAUDIT_CACHE_DIR"])


def records_in(root: Path) -> list[Path]:
    """The record files of the cache in ``root``."""
    return sorted((root / "files").glob("*.rec"))


def record_of(root: Path, content: bytes) -> Path:
    """Where the record of a file with this content is: named by its digest."""
    return root / "files" / (hashlib.blake2b(content, digest_size=16).hexdigest() + ".rec")


@pytest.fixture(scope="module")
def small_db(tmp_path_factory) -> Path:
    """Three files: two lenses with several models, and one broken file."""
    directory = tmp_path_factory.mktemp("small-db")
    (directory / "a.xml").write_text(
        lens_xml(
            POLY3.format(k1="-0.1"),
            '<distortion model="ptlens" focal="12" a="0.01" b="-0.05" c="0.02"/>',
            '<distortion model="poly5" focal="14" k1="-0.2" k2="0.01"/>',
        )
    )
    (directory / "b.xml").write_text(
        lens_xml(POLY3.format(k1="0.05"), '<distortion model="acm" focal="20" k1="1"/>')
    )
    (directory / "c.xml").write_text("<lensdatabase><lens><maker>X</maker>")
    return directory


def scan(paths: list[Path], output_format: str, cache: Path, *options: str):
    """`lensaudit scan PATHS -f FORMAT` with the cache in ``cache``: (stdout, stderr)."""
    result = CliRunner().invoke(
        main,
        ["scan", *map(str, paths), "-f", output_format, *options],
        env={"LENSAUDIT_CACHE_DIR": str(cache)},
    )
    assert result.exit_code == 0, result.output
    return result.stdout, result.stderr


def scan_output(paths: list[Path], output_format: str, cache: Path, *options: str) -> str:
    """What the scan prints, after checking it says nothing on stderr."""
    stdout, stderr = scan(paths, output_format, cache, *options)
    assert stderr == ""
    return stdout


def snapshot(audit: pipeline.Audit):
    """Everything an audit reports, with NaN made comparable."""
    columns = {
        name: ["nan" if isinstance(v, float) and math.isnan(v) else v for v in values]
        for name, values in audit.columns().items()
    }
    return columns, [(f.name, f.entries, f.error) for f in audit.files]


def comparable(rows) -> list[str]:
    """Rows or records as texts: NaN equals NaN, and 0.0 differs from -0.0."""
    return [repr(tuple(row)) for row in rows]


@pytest.fixture
def parses(monkeypatch) -> list[bytes]:
    """The contents parsed from now on (in this process: small inputs are parsed here)."""
    calls: list[bytes] = []
    real = xml_module.parse

    def counting(data, *arguments, **options):
        calls.append(data)
        return real(data, *arguments, **options)

    monkeypatch.setattr(xml_module, "parse", counting)
    return calls


@pytest.fixture
def solves(monkeypatch) -> list[int]:
    """How many rows had their metrics computed from now on."""
    calls: list[int] = []
    real = pipeline.metric_columns

    def counting(columns, *memo):
        calls.append(len(columns["status"]))
        return real(columns, *memo)

    monkeypatch.setattr(pipeline, "metric_columns", counting)
    return calls


def contents(directory: Path) -> list[bytes]:
    return sorted(path.read_bytes() for path in directory.glob("*.xml"))


# --- a warm run gives what a cold one gives ----------------------------------------------


@pytest.mark.parametrize("output_format", FORMATS)
def test_a_warm_scan_prints_byte_for_byte_what_a_scan_without_the_cache_prints(
    bundled_db, cache_root, output_format
):
    uncached = scan_output([bundled_db], output_format, cache_root, "--no-cache")
    assert records_in(cache_root) == []
    cold = scan_output([bundled_db], output_format, cache_root)
    assert len(records_in(cache_root)) == len(list(bundled_db.glob("*.xml")))
    warm = scan_output([bundled_db], output_format, cache_root)
    assert cold == uncached and warm == uncached
    assert uncached.count("\n") > (5000 if output_format != "table" else 10)


@settings(max_examples=6, deadline=None)
@given(st.data())
def test_any_files_scanned_in_any_order_of_formats_print_the_uncached_output(bundled_db, data):
    files = sorted(bundled_db.glob("*.xml"))
    chosen = data.draw(st.lists(st.sampled_from(files), min_size=1, max_size=4, unique=True))
    order = data.draw(st.permutations(FORMATS))
    with tempfile.TemporaryDirectory() as scratch:
        database = Path(scratch, "db")
        database.mkdir()
        for file in chosen:
            shutil.copy(file, database / file.name)
        cache = Path(scratch, "cache")
        uncached = {f: scan_output([database], f, cache, "--no-cache") for f in FORMATS}
        assert not cache.exists()
        for _ in range(2):  # cold, then warm
            for output_format in order:
                assert scan_output([database], output_format, cache) == uncached[output_format]


def test_a_warm_audit_parses_no_xml_and_computes_no_metric(small_db, parses, solves):
    pipeline.run(small_db, cache=True)
    assert sorted(parses) == contents(small_db) and sum(solves) == 6
    parses.clear()
    solves.clear()
    pipeline.run(small_db, cache=True)
    assert parses == [] and solves == []


def test_a_warm_audit_gives_the_columns_and_summary_of_a_cold_one(bundled_db):
    cold = pipeline.run(bundled_db, cache=False)
    pipeline.run(bundled_db, cache=True)  # fills the cache
    warm = pipeline.run(bundled_db, cache=True)
    assert snapshot(warm) == snapshot(cold)
    assert warm.summary.to_dict() == cold.summary.to_dict()


def test_cached_tables_equal_a_fresh_read_of_the_bundled_database(bundled_db, parses):
    fresh = read(bundled_db, calibrations=True)
    read(bundled_db, cache=Cache(), calibrations=True)
    parses.clear()
    cached = read(bundled_db, cache=Cache(), calibrations=True)
    assert parses == []  # every file from the cache
    assert [f.name for f in cached.files] == [f.name for f in fresh.files]
    assert comparable(cached.entries()) == comparable(fresh.entries())
    assert comparable(cached.source_files()) == comparable(fresh.source_files())
    for mine, theirs in zip(cached.files, fresh.files, strict=True):
        assert comparable(mine.lenses) == comparable(theirs.lenses)
        assert mine.omitted == theirs.omitted and mine.lens_of_row == theirs.lens_of_row
        assert comparable(mine.vignetting) == comparable(theirs.vignetting)
        assert comparable(mine.tca) == comparable(theirs.tca)


def test_a_read_with_calibrations_after_one_without_reads_them(small_db):
    read(small_db, cache=Cache())
    found = read(small_db, cache=Cache(), calibrations=True)
    assert all(f.vignetting is not None and f.tca is not None for f in found.files)
    assert comparable(found.rows("tca")[1]) == comparable(
        read(small_db, calibrations=True).rows("tca")[1]
    )


def test_broken_files_and_statuses_survive_the_cache(write_xml):
    write_xml("<lensdatabase><lens>", "broken.xml")
    directory = write_xml(lens_xml('<distortion model="acm" focal="10" k1="1"/>'), "o.xml").parent
    fresh = read(directory)
    read(directory, cache=Cache())
    cached = read(directory, cache=Cache())
    assert comparable(cached.entries()) == comparable(fresh.entries())
    assert [f.error for f in cached.files] == [f.error for f in fresh.files]
    assert {e.status for e in cached.entries()} == {"xml_error", "unknown_model"}


def test_a_cold_audit_with_the_cache_parses_each_file_once(small_db, parses):
    pipeline.run(small_db, cache=True)
    assert sorted(parses) == contents(small_db)


@pytest.mark.parametrize("output_format", ["csv", "json"])
def test_rows_of_a_changed_file_are_printed_beside_cached_ones(bundled_db, tmp_path, output_format):
    database = tmp_path / "db"
    database.mkdir()
    for name in ("slr-tokina.xml", "slr-sigma.xml", "mil-olympus.xml"):
        shutil.copy(bundled_db / name, database / name)
    cache = tmp_path / "cache"
    scan_output([database], output_format, cache)
    changed = database / "slr-tokina.xml"
    changed.write_text(changed.read_text().replace('k1="', 'k1="-', 3))
    assert scan_output([database], output_format, cache) == scan_output(
        [database], output_format, cache, "--no-cache"
    )


def test_a_warm_scan_does_not_import_numpy(cache_root, bundled_db, tmp_path):
    # The bundled database's entries, and one that only numpy's array code audits
    # (a tangency, 1 - 3 w + 2.25 w^2): the cold scan imports numpy, the warm one not.
    database = tmp_path / "db"
    database.mkdir()
    for source in bundled_db.glob("*.xml"):
        (database / source.name).write_bytes(source.read_bytes())
    (database / "tangent.xml").write_text(
        "<lensdatabase><lens><maker>M</maker><model>L</model><mount>X</mount><calibration>"
        '<distortion model="poly5" focal="10" k1="-1" k2="0.45"/>'
        "</calibration></lens></lensdatabase>"
    )
    script = (
        "import io, sys\n"
        "from lensaudit.pipeline import run\n"
        "from lensaudit.formats import writer\n"
        f"writer('csv')(run({str(database)!r}, cache=True), io.StringIO())\n"
        "print('numpy' in sys.modules)\n"
    )
    env = dict(os.environ, LENSAUDIT_CACHE_DIR=str(cache_root))
    found = [
        subprocess.run(
            [sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True
        ).stdout.strip()
        for _ in range(2)
    ]
    assert found == ["True", "False"]


# --- the key is the content ---------------------------------------------------------------


def test_each_file_has_one_record_named_by_the_digest_of_its_bytes(small_db, cache_root):
    pipeline.run(small_db, cache=True)
    assert records_in(cache_root) == sorted(record_of(cache_root, c) for c in contents(small_db))


def test_the_same_bytes_under_another_name_are_neither_parsed_nor_solved_again(
    small_db, tmp_path, cache_root, parses, solves
):
    pipeline.run(small_db, cache=True)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.copy(small_db / "a.xml", elsewhere / "renamed.xml")
    parses.clear()
    solves.clear()
    audit = pipeline.run(elsewhere, cache=True)
    assert parses == [] and solves == []
    assert set(audit.column("file")) == {"renamed.xml"}
    assert snapshot(audit) == snapshot(pipeline.run(elsewhere, cache=False))


@pytest.mark.parametrize("how", ["renamed", "copied"])
def test_a_record_under_the_name_of_another_content_is_no_record(
    small_db, tmp_path, cache_root, how
):
    # The records of two files, one put in the other's place: what is read for a
    # content must be what was made of that content, or nothing.
    pipeline.run(small_db, cache=True)
    first, second = sorted(contents(small_db))[:2]
    mine, other = record_of(cache_root, first), record_of(cache_root, second)
    if how == "renamed":
        os.replace(mine, other)
    else:
        shutil.copy(mine, other)
    expected = scan_output([small_db], "csv", tmp_path / "fresh")
    assert scan_output([small_db], "csv", cache_root) == expected


def test_one_file_named_by_its_directory_and_by_its_path_shows_each_name(write_xml, cache_root):
    path = write_xml(lens_xml(POLY3.format(k1="-0.1")), "a.xml")
    by_directory = scan_output([path.parent], "csv", cache_root)
    by_file = scan_output([path], "csv", cache_root)
    assert len(records_in(cache_root)) == 1  # one content, one record
    assert by_directory.splitlines()[1].startswith("a.xml,")
    assert by_file.splitlines()[1].startswith(f"{path},")
    assert by_file == scan_output([path], "csv", cache_root, "--no-cache")


def rewrite_keeping_size_and_time(path: Path, text: str) -> None:
    """Replace a file's content by one of the same size and restore its times, as
    ``git checkout`` or ``rsync -t`` can leave it."""
    before = path.stat()
    assert len(text.encode()) == before.st_size
    path.write_text(text)
    os.utime(path, ns=(before.st_atime_ns, before.st_mtime_ns))
    after = path.stat()
    assert (after.st_size, after.st_mtime_ns) == (before.st_size, before.st_mtime_ns)


def test_a_changed_byte_with_the_same_size_and_time_is_read_again(write_xml):
    path = write_xml(lens_xml(POLY3.format(k1="-0.1")))
    assert [e.k1 for e in read(path, cache=Cache()).entries()] == [-0.1]
    rewrite_keeping_size_and_time(path, lens_xml(POLY3.format(k1="-0.3")))
    assert [e.k1 for e in read(path, cache=Cache()).entries()] == [-0.3]


def test_a_changed_byte_with_the_same_size_and_time_is_audited_again(write_xml):
    path = write_xml(lens_xml(POLY3.format(k1="-0.1")))
    assert pipeline.run(path.parent, cache=True).column("r_max") == [
        pytest.approx(poly3_r_max(-0.1), rel=1e-12)
    ]
    rewrite_keeping_size_and_time(path, lens_xml(POLY3.format(k1="-0.2")))
    again = pipeline.run(path.parent, cache=True)
    assert again.column("k1") == [-0.2]
    assert again.column("r_max") == [pytest.approx(poly3_r_max(-0.2), rel=1e-12)]


def test_a_changed_byte_with_the_same_size_and_time_is_scanned_again_by_the_cli(
    write_xml, cache_root
):
    path = write_xml(lens_xml(POLY3.format(k1="-0.1")))
    first = scan_output([path], "csv", cache_root)
    rewrite_keeping_size_and_time(path, lens_xml(POLY3.format(k1="-0.4")))
    second = scan_output([path], "csv", cache_root)
    assert ",-0.1," in first and ",-0.4," in second
    assert second == scan_output([path], "csv", cache_root, "--no-cache")


def test_a_file_changed_to_one_that_never_folds_is_audited_again(write_xml):
    path = write_xml(lens_xml(POLY3.format(k1="-0.1")))
    assert pipeline.run(path.parent, cache=True).column("r_max")[0] != math.inf
    path.write_text(lens_xml(POLY3.format(k1="0.1")))
    assert pipeline.run(path.parent, cache=True).column("r_max") == [math.inf]


# --- a damaged or foreign record is ignored and rebuilt, without a word --------------------


#: The size of a fingerprint and of a content's digest.
DIGEST_SIZE = 16


def head_and_sections(data: bytes) -> tuple[bytes, dict[str, tuple[bytes, bytes]]]:
    """A record as documented: the header with the fingerprint and the digest of
    the content, then the sections."""
    end = data.index(fingerprint()) + len(fingerprint()) + DIGEST_SIZE
    return data[:end], marshal.loads(data[end:])


def sealed(value: object) -> tuple[bytes, bytes]:
    body = marshal.dumps(value)
    return hashlib.blake2b(body, digest_size=16).digest(), body


def forged(data: bytes, head: bytes | None = None, reseal: bool = True) -> bytes:
    """The record with every r_max of its metrics set to 42 (its seal remade, or
    kept as it was), and ``head`` in place of its header if given."""
    old_head, sections = head_and_sections(data)
    seal, body = sections["metrics"]
    metrics = marshal.loads(body)
    metrics["r_max"] = [42.0] * len(metrics["r_max"])
    new_seal, new_body = sealed(metrics)
    sections["metrics"] = (new_seal if reseal else seal, new_body)
    return (old_head if head is None else head) + marshal.dumps(sections)


@pytest.fixture
def primed(small_db, cache_root) -> tuple[Path, bytes]:
    """The small database audited with an empty cache: the record of a.xml, and its bytes."""
    pipeline.run(small_db, cache=True)
    path = record_of(cache_root, (small_db / "a.xml").read_bytes())
    return path, path.read_bytes()


@pytest.fixture(scope="module")
def uncached(small_db) -> tuple:
    return snapshot(pipeline.run(small_db, cache=False))


def assert_ignored_and_rebuilt(small_db: Path, record: Path, original: bytes, uncached) -> None:
    """A warm audit gives what an audit without the cache gives, and the record is
    made again as it was."""
    assert snapshot(pipeline.run(small_db, cache=True)) == uncached
    assert record.read_bytes() == original


def test_a_record_sealed_as_documented_is_served(small_db, primed):
    # Shows that the damage below is looked for in what the cache does read.
    path, data = primed
    path.write_bytes(forged(data))
    assert 42.0 in pipeline.run(small_db, cache=True).column("r_max")


def test_a_section_changed_under_its_old_seal_is_not_served(small_db, primed, uncached):
    path, data = primed
    path.write_bytes(forged(data, reseal=False))
    assert_ignored_and_rebuilt(small_db, path, data, uncached)


@pytest.mark.parametrize("section", ["tables", "metrics"])
def test_a_flipped_byte_in_a_section_is_not_served(small_db, primed, uncached, section):
    path, data = primed
    _, sections = head_and_sections(data)
    body = sections[section][1]
    position = data.index(body) + len(body) // 2
    path.write_bytes(data[:position] + bytes([data[position] ^ 0x01]) + data[position + 1 :])
    assert_ignored_and_rebuilt(small_db, path, data, uncached)


def test_a_record_of_another_fingerprint_is_not_served(small_db, primed, uncached):
    path, data = primed
    head, _ = head_and_sections(data)
    start = head.index(fingerprint())
    other = head[:start] + bytes(b ^ 0xFF for b in fingerprint()) + head[start + DIGEST_SIZE :]
    path.write_bytes(forged(data, head=other))
    assert_ignored_and_rebuilt(small_db, path, data, uncached)


def test_a_record_with_another_header_is_not_served(small_db, primed, uncached):
    path, data = primed
    head, _ = head_and_sections(data)
    # The same length, the fingerprint in its place: only the header differs.
    other = bytes([head[0] ^ 0x20]) + head[1:]
    path.write_bytes(forged(data, head=other))
    assert_ignored_and_rebuilt(small_db, path, data, uncached)


@pytest.mark.parametrize("kept", [0, 1 / 3, 2 / 3, -1])
def test_a_truncated_record_is_not_served(small_db, primed, uncached, kept):
    path, data = primed
    path.write_bytes(data[:-1] if kept == -1 else data[: int(len(data) * kept)])
    assert_ignored_and_rebuilt(small_db, path, data, uncached)


@pytest.mark.parametrize("garbage", [b"\x00garbage", marshal.dumps({"tables": 1}), b"lensaudit"])
def test_garbage_in_place_of_a_record_is_not_served(small_db, primed, uncached, garbage):
    path, data = primed
    path.write_bytes(garbage)
    assert_ignored_and_rebuilt(small_db, path, data, uncached)


def test_a_damaged_record_is_rebuilt_without_a_word(small_db, cache_root, primed, parses):
    path, data = primed
    expected = scan_output([small_db], "csv", cache_root, "--no-cache")
    path.write_bytes(data[: len(data) // 2])
    stdout, stderr = scan([small_db], "csv", cache_root)
    assert (stdout, stderr) == (expected, "")
    assert path.read_bytes() == data  # made again, as it was
    parses.clear()
    assert scan_output([small_db], "csv", cache_root) == expected
    assert parses == []


def test_one_damaged_record_costs_only_its_file(small_db, primed, uncached, parses):
    path, data = primed
    path.write_bytes(b"\x00" + data[1:])
    parses.clear()
    assert snapshot(pipeline.run(small_db, cache=True)) == uncached
    assert parses == [(small_db / "a.xml").read_bytes()]


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_any_flipped_bytes_in_a_record_give_the_uncached_output(small_db, data):
    with tempfile.TemporaryDirectory() as scratch:
        cache = Path(scratch)
        expected = {f: scan_output([small_db], f, cache, "--no-cache") for f in ("csv", "json")}
        scan_output([small_db], "csv", cache)
        path = data.draw(st.sampled_from(records_in(cache)))
        path.write_bytes(flipped(path.read_bytes(), data.draw(FLIPS)))
        for output_format in ("csv", "json"):
            assert scan_output([small_db], output_format, cache) == expected[output_format]


def test_a_directory_in_place_of_a_record_only_costs_speed(small_db, primed, uncached):
    path, _ = primed
    path.unlink()
    path.mkdir()
    assert snapshot(pipeline.run(small_db, cache=True)) == uncached
    assert snapshot(pipeline.run(small_db, cache=True)) == uncached


def run_in_a_thread(paths, seconds: float = 30):
    """pipeline.run(paths, cache=True) in a thread: (the audit or None, whether it hung)."""
    outcome: list = []
    worker = threading.Thread(
        target=lambda: outcome.append(pipeline.run(paths, cache=True)), daemon=True
    )
    worker.start()
    worker.join(timeout=seconds)
    return worker, outcome


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes on this system")
def test_a_fifo_in_place_of_a_record_does_not_hang(small_db, primed, uncached):
    path, _ = primed
    path.unlink()
    os.mkfifo(path)
    worker, outcome = run_in_a_thread(small_db, seconds=5)
    hung = worker.is_alive()
    if hung:  # let the reader go: a writer that closes at once gives it an empty record
        os.close(os.open(path, os.O_WRONLY | os.O_NONBLOCK))
        worker.join(timeout=30)
    assert not hung
    assert snapshot(outcome[0]) == uncached


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes on this system")
def test_a_cached_file_replaced_by_a_fifo_does_not_hang(write_xml):
    path = write_xml(lens_xml(POLY3.format(k1="-0.1")))
    pipeline.run(path.parent, cache=True)
    path.unlink()
    os.mkfifo(path)
    worker, outcome = run_in_a_thread(path.parent)
    assert not worker.is_alive()
    assert snapshot(outcome[0]) == snapshot(pipeline.run(path.parent, cache=False))
    assert outcome[0].column("status") == ["unreadable"]


# --- a cache that cannot be written only costs speed ---------------------------------------


def cli(*arguments: str, cache: Path, prefix: list[str] | None = None):
    """`lensaudit ARGUMENTS` in a fresh process with the cache in ``cache``."""
    env = dict(os.environ, LENSAUDIT_CACHE_DIR=str(cache))
    command = [sys.executable, *(prefix or ["-m", "lensaudit"]), *arguments]
    return subprocess.run(command, env=env, capture_output=True, text=True)


def test_an_unwritable_cache_directory_is_silent(small_db, tmp_path):
    blocker = tmp_path / "not-a-directory"
    blocker.write_text("")
    expected = cli("scan", str(small_db), "-f", "csv", "--no-cache", cache=tmp_path / "unused")
    for _ in range(2):
        found = cli("scan", str(small_db), "-f", "csv", cache=blocker / "cache")
        assert (found.returncode, found.stderr, found.stdout) == (0, "", expected.stdout)
    assert blocker.read_text() == ""


def test_a_files_directory_that_is_a_file_is_silent(small_db, cache_root):
    cache_root.mkdir()
    (cache_root / "files").write_text("not a directory")
    expected = scan_output([small_db], "csv", cache_root, "--no-cache")
    assert scan([small_db], "csv", cache_root) == (expected, "")
    assert (cache_root / "files").read_text() == "not a directory"


@pytest.mark.skipif(sys.platform == "win32", reason="file size limits are POSIX")
def test_a_full_disk_is_silent_and_leaves_no_partial_record(small_db, cache_root):
    # Writes beyond 100 bytes fail (EFBIG), as they would on a full disk.
    limited = [
        "-c",
        "import resource, runpy, sys\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (100, 100))\n"
        "sys.argv[0] = 'lensaudit'\n"
        "runpy.run_module('lensaudit', run_name='__main__')\n",
    ]
    arguments = ("scan", str(small_db), "--format", "csv")
    full = cli(*arguments, cache=cache_root, prefix=limited)
    expected = cli(*arguments, "--no-cache", cache=cache_root)
    assert (full.returncode, full.stderr, full.stdout) == (0, "", expected.stdout)
    assert [p for p in cache_root.rglob("*") if p.is_file()] == []


# --- bounded ---------------------------------------------------------------------------------


def one_entry_files(directory: Path, count: int) -> list[Path]:
    """``count`` files of one entry each, of equal size and different content."""
    directory.mkdir()
    paths = []
    for index in range(count):
        path = directory / f"{index}.xml"
        path.write_text(lens_xml(POLY3.format(k1=f"-0.{index + 1}")))
        paths.append(path)
    return paths


def aged(path: Path, seconds: float) -> None:
    then = time.time() - seconds
    os.utime(path, (then, then))


def test_at_most_max_records_are_kept(tmp_path, cache_root, monkeypatch):
    monkeypatch.setattr(cache_module, "MAX_RECORDS", 3)
    for path in one_entry_files(tmp_path / "dbs", 7):
        pipeline.run(path, cache=True)
        assert 1 <= len(records_in(cache_root)) <= 3
    pipeline.run(tmp_path / "dbs", cache=True)  # seven records wanted at once
    assert len(records_in(cache_root)) == 3


def test_the_least_recently_used_records_are_evicted(tmp_path, cache_root, monkeypatch):
    monkeypatch.setattr(cache_module, "MAX_RECORDS", 3)
    a, b, c, d = one_entry_files(tmp_path / "dbs", 4)
    record = {path: record_of(cache_root, path.read_bytes()) for path in (a, b, c, d)}
    for age, path in zip((3000, 2000, 1000), (a, b, c), strict=True):
        pipeline.run(path, cache=True)
        aged(record[path], age)
    pipeline.run(a, cache=True)  # the oldest, used again: b is now the least recently used
    pipeline.run(d, cache=True)
    assert records_in(cache_root) == sorted((record[a], record[c], record[d]))


def test_records_beyond_the_byte_bound_are_evicted(tmp_path, cache_root, monkeypatch):
    a, b, c = one_entry_files(tmp_path / "dbs", 3)
    record = {path: record_of(cache_root, path.read_bytes()) for path in (a, b, c)}
    for age, path in zip((2000, 1000), (a, b), strict=True):
        pipeline.run(path, cache=True)
        aged(record[path], age)
    size = record[a].stat().st_size
    assert record[b].stat().st_size == size
    monkeypatch.setattr(cache_module, "MAX_BYTES", 2 * size + size // 2)
    pipeline.run(c, cache=True)
    assert records_in(cache_root) == sorted((record[b], record[c]))


def test_abandoned_temporary_files_are_removed_and_other_files_kept(
    small_db, cache_root, running_pid
):
    # A temporary file is abandoned when the process named in it is gone
    # (killed with SIGKILL, say), whatever its age; another run's is kept.
    files = cache_root / "files"
    files.mkdir(parents=True)
    gone = ended_pid()
    abandoned = [files / f".0123.rec.{gone}.0.tmp", files / f"0124.rec.{gone}.tmp"]
    in_progress = [files / f".4567.rec.{running_pid}.3.tmp", files / f"4568.rec.{running_pid}.tmp"]
    old_and_nameless = files / "0125.rec.tmp"
    other = files / "notes.txt"
    beside = cache_root / "history-0.1.0.sqlite3"
    for path in (*abandoned, *in_progress, old_and_nameless, other, beside):
        path.write_bytes(b"x")
        aged(path, 2 * 3600 if path not in abandoned else 0)
    pipeline.run(small_db, cache=True)
    assert not any(path.exists() for path in (*abandoned, old_and_nameless))
    assert all(path.exists() for path in (*in_progress, other, beside))


# --- records are valid for the code that made them -----------------------------------------

FINGERPRINT_OF_A_COPY = (
    "import sys\n"
    "sys.path.insert(0, sys.argv[1])\n"
    "import lensaudit.read.cache as cache\n"
    "assert cache.__file__.startswith(sys.argv[1]), cache.__file__\n"
    "print(cache.fingerprint().hex())\n"
)


def fingerprint_of(source: Path) -> str:
    """The fingerprint lensaudit computes when imported from ``source`` (a copy)."""
    done = subprocess.run(
        [sys.executable, "-c", FINGERPRINT_OF_A_COPY, str(source)],
        capture_output=True,
        text=True,
        check=True,
    )
    return done.stdout.strip()


@pytest.mark.parametrize(
    "module",
    [
        "read/tables.py",
        "read/xml.py",
        "read/records.py",
        "normalizer.py",
        "metrics.py",
        "pipeline.py",
        "solver/kernel.py",
        "solver/arrays.py",
        "solver/constants.py",
    ],
)
def test_the_fingerprint_changes_with_the_code_whose_output_is_kept(tmp_path, module):
    package = tmp_path / "lensaudit"
    shutil.copytree(
        Path(pipeline.__file__).parent, package, ignore=shutil.ignore_patterns("__pycache__")
    )
    before = fingerprint_of(tmp_path)
    with (package / module).open("a") as stream:
        stream.write("\n# an edit\n")
    assert fingerprint_of(tmp_path) != before


# --- the cache as a library object ----------------------------------------------------------


def test_a_section_put_and_saved_is_got_back_by_another_cache(tmp_path):
    digest = hashlib.blake2b(b"content", digest_size=16).digest()
    value = {"x": [1.5, -0.0, "text", None], "y": (b"\x00\x01", True)}
    first = Cache(tmp_path)
    assert first.get(digest, "tables") is None
    first.put(digest, "tables", value)
    assert Cache(tmp_path).get(digest, "tables") is None  # kept in memory until saved
    first.save()
    again = Cache(tmp_path)
    assert repr(again.get(digest, "tables")) == repr(value)
    assert again.get(digest, "metrics") is None


# --- file names and where the cache is ------------------------------------------------------


def test_a_file_name_that_is_not_utf8_is_scanned_with_and_without_cache(tmp_path, cache_root):
    directory = tmp_path / "db"
    directory.mkdir()
    name = os.fsdecode(b"caf\xff.xml")
    try:
        (directory / name).write_text(lens_xml(POLY3.format(k1="-0.1")))
    except (OSError, UnicodeError):
        pytest.skip("this file system does not take file names that are not UTF-8")
    scans = [scan_output([directory], "csv", cache_root, *o) for o in (["--no-cache"], [], [])]
    assert scans[0].count("\n") == 2 and ",-0.1," in scans[0]
    assert scans[1] == scans[0] and scans[2] == scans[0]


def test_the_cache_is_in_lensaudit_cache_dir(small_db, tmp_path, monkeypatch):
    monkeypatch.setenv("LENSAUDIT_CACHE_DIR", str(tmp_path / "explicit"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    pipeline.run(small_db, cache=True)
    assert len(records_in(tmp_path / "explicit")) == 3
    assert not (tmp_path / "xdg").exists()


def test_the_cache_is_in_xdg_cache_home_without_lensaudit_cache_dir(
    small_db, tmp_path, monkeypatch
):
    monkeypatch.delenv("LENSAUDIT_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    pipeline.run(small_db, cache=True)
    assert len(records_in(tmp_path / "xdg" / "lensaudit")) == 3


def test_without_either_variable_the_cache_is_in_the_home_directory(tmp_path, monkeypatch):
    monkeypatch.delenv("LENSAUDIT_CACHE_DIR")
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path))
    assert cache_dir() == tmp_path / ".cache" / "lensaudit"


def test_a_relative_xdg_cache_home_is_ignored(tmp_path, monkeypatch):
    monkeypatch.delenv("LENSAUDIT_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/cache")
    monkeypatch.setenv("HOME", str(tmp_path))
    assert cache_dir() == tmp_path / ".cache" / "lensaudit"
