"""The parse cache: same entries and metrics as a fresh parse, never stale, never trusted
when damaged, bounded, and in the directory the environment names."""

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
from array import array
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

import lensaudit.cache as cache_module
from conftest import lens_xml
from damage import FLIPS, flipped
from lensaudit import loader, pipeline, store
from lensaudit.cache import ParseCache, cache_dir, pack_entries, unpack_entries
from lensaudit.cli import main
from lensaudit.formats import csv_format, json_format
from lensaudit.loader import DistortionEntry
from lensaudit.pipeline import run


def normalized(entries):
    return [
        tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in e) for e in entries
    ]


def snapshot(audit):
    """Everything an audit reports, with NaN made comparable."""
    columns = {
        name: ["nan" if isinstance(v, float) and math.isnan(v) else v for v in values]
        for name, values in audit.columns().items()
    }
    return columns, [(f.name, f.entries, f.error) for f in audit.files]


@pytest.fixture
def cache_dir_path() -> Path:
    """The cache directory every test is given (see conftest.py)."""
    return Path(os.environ["LENSAUDIT_CACHE_DIR"])


def cache_files(directory: Path) -> list[Path]:
    return sorted(directory.glob("parsed-*.cache"))


def the_cache_file(directory: Path) -> Path:
    (found,) = cache_files(directory)
    return found


def load_with_cache(paths, directory):
    targets = loader.expand(paths)
    cache = ParseCache([path for path, _ in targets], directory)
    result = loader.load_files(targets, cache)
    cache.save()
    return result


def count_parses(monkeypatch) -> list[str]:
    """Names of the files parsed from now on (the cache parses none itself)."""
    calls: list[str] = []
    real = loader.read_bytes
    real_parse = pipeline._parse

    def counting(data, name):
        calls.append(name)
        return real(data, name)

    def counting_parse(job, *arguments, **options):  # the audit's own reading
        calls.append(job.name)
        return real_parse(job, *arguments, **options)

    monkeypatch.setattr(loader, "read_bytes", counting)
    monkeypatch.setattr(pipeline, "_parse", counting_parse)
    return calls


POLY3 = '<distortion model="poly3" focal="10" k1="{k1}"/>'


def poly3_r_max(k1: float) -> float:
    """r_max of poly3, D(r) = r (1 - k1 + k1 r^2): D'(r) = 0 at r^2 = (k1 - 1) / (3 k1)."""
    return math.sqrt((k1 - 1) / (3 * k1))


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


# --- the cache gives what a fresh parse gives --------------------------------------------


def test_cached_entries_equal_a_fresh_parse_of_the_bundled_database(bundled_db, cache_dir_path):
    fresh = loader.load(bundled_db)
    load_with_cache(bundled_db, cache_dir_path)
    assert any(cache_dir_path.iterdir())
    cached = load_with_cache(bundled_db, cache_dir_path)
    assert normalized(cached.entries) == normalized(fresh.entries)
    assert [f.name for f in cached.files] == [f.name for f in fresh.files]


def test_broken_files_and_statuses_survive_the_cache(write_xml, cache_dir_path):
    write_xml("<lensdatabase><lens>", "broken.xml")
    directory = write_xml(
        lens_xml('<distortion model="acm" focal="10" k1="1"/>'), "other.xml"
    ).parent
    fresh = loader.load(directory)
    load_with_cache(directory, cache_dir_path)
    cached = load_with_cache(directory, cache_dir_path)
    assert normalized(cached.entries) == normalized(fresh.entries)
    assert [f.error for f in cached.files] == [f.error for f in fresh.files]
    assert {e.status for e in cached.entries} == {"xml_error", "unknown_model"}


def test_a_warm_audit_gives_the_same_columns_as_a_cold_one(bundled_db):
    cold = run(bundled_db, cache=False)
    run(bundled_db, cache=True)  # fills the cache
    warm = run(bundled_db, cache=True)
    assert "metrics" not in warm.__dict__  # not computed: from the cache
    assert all(part.packed_metrics is not None for part in warm._parts)
    assert snapshot(warm) == snapshot(cold)
    assert warm.summary.to_dict() == cold.summary.to_dict()


def test_a_warm_audit_parses_no_xml(small_db, monkeypatch):
    run(small_db, cache=True)
    calls = count_parses(monkeypatch)
    run(small_db, cache=True)
    assert calls == []


def test_a_cold_audit_with_the_cache_parses_each_file_once(small_db, monkeypatch):
    calls = count_parses(monkeypatch)
    run(small_db, cache=True)
    assert sorted(calls) == ["a.xml", "b.xml", "c.xml"]


def test_scan_from_a_warm_cache_does_not_import_numpy(cache_dir_path, bundled_db, tmp_path):
    # The bundled database's entries, and one that only numpy's array code audits
    # (a tangency, 1 - 3 w + 2.25 w^2): the cold scan imports numpy.
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
    env = dict(os.environ, LENSAUDIT_CACHE_DIR=str(cache_dir_path))
    first = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True
    )
    second = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True
    )
    assert (first.stdout.strip(), second.stdout.strip()) == ("True", "False")


texts = st.text(max_size=12)  # includes the separators "\0", "\1", "\2" of packed texts
floats = st.floats(allow_nan=True, allow_infinity=True)
entries_strategy = st.lists(
    st.builds(
        DistortionEntry,
        file=st.just("x.xml"),
        line=st.integers(0, 2**62),
        maker=texts,
        lens=texts,
        mounts=st.lists(texts, max_size=3).map(tuple),
        type=texts,
        crop_factor=floats,
        aspect_ratio=floats,
        model=texts,
        focal=floats,
        real_focal=floats,
        a=floats,
        b=floats,
        c=floats,
        k1=floats,
        k2=floats,
        status=texts,
        message=texts,
    ),
    max_size=6,
)


@settings(max_examples=300, deadline=None)
@given(entries_strategy)
def test_any_entries_come_back_from_a_record_unchanged(entries):
    def exact(entry):  # repr tells -0.0 from 0.0 and makes NaN equal to itself
        return tuple(repr(v) if isinstance(v, float) else v for v in entry)

    record = marshal.loads(marshal.dumps(pack_entries(entries)))
    assert list(map(exact, unpack_entries(record, "x.xml"))) == list(map(exact, entries))


# --- rows rendered by the output formats -------------------------------------------------

FORMATS = ("table", "csv", "json")


def scan_output(paths: list[Path], output_format: str, cache: Path, *options: str) -> str:
    """What `lensaudit scan PATHS -f FORMAT` prints, with the cache in ``cache``."""
    result = CliRunner().invoke(
        main,
        ["scan", *map(str, paths), "-f", output_format, *options],
        env={"LENSAUDIT_CACHE_DIR": str(cache)},
    )
    assert result.exit_code == 0, result.output
    return result.output


@settings(max_examples=8, deadline=None)
@given(st.data())
def test_cached_rows_give_the_uncached_output_in_every_format(bundled_db, data):
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
        for output_format in order:  # parsed, or taken from the cache with rows added
            assert scan_output([database], output_format, cache) == uncached[output_format]
        for output_format in order:  # every format's rows from the cache
            assert scan_output([database], output_format, cache) == uncached[output_format]


@pytest.mark.parametrize("output_format", ["csv", "json"])
def test_rows_of_a_changed_file_are_rendered_beside_cached_ones(
    bundled_db, tmp_path, output_format
):
    database = tmp_path / "db"
    database.mkdir()
    for name in ("slr-tokina.xml", "slr-sigma.xml", "mil-olympus.xml"):
        shutil.copy(bundled_db / name, database / name)
    cache = tmp_path / "cache"
    scan_output([database], output_format, cache)
    changed = database / "slr-tokina.xml"  # the fewest entries: the others keep their rows
    changed.write_text(changed.read_text().replace('k1="', 'k1="-', 3))
    assert scan_output([database], output_format, cache) == scan_output(
        [database], output_format, cache, "--no-cache"
    )


def test_a_warm_scan_renders_no_row(small_db, cache_dir_path, monkeypatch):
    first = {f: scan_output([small_db], f, cache_dir_path) for f in ("csv", "json")}

    def fail(*arguments):
        raise AssertionError("rendered again")

    for module in (csv_format, json_format):
        monkeypatch.setattr(module, "row_texts", fail)
        monkeypatch.setattr(module, "rows", fail)
    assert {f: scan_output([small_db], f, cache_dir_path) for f in ("csv", "json")} == first


def test_rows_rendered_for_one_file_name_do_not_serve_another(write_xml, cache_dir_path):
    path = write_xml(lens_xml(POLY3.format(k1="-0.1")), "a.xml")
    by_directory = scan_output([path.parent], "csv", cache_dir_path)
    by_file = scan_output([path], "csv", cache_dir_path)  # the same file: the same cache file
    assert len(cache_files(cache_dir_path)) == 1
    assert by_directory.splitlines()[1].startswith("a.xml,")
    assert by_file.splitlines()[1].startswith(f"{path},")
    assert by_file == scan_output([path], "csv", cache_dir_path, "--no-cache")


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_any_flipped_bytes_in_a_cache_with_rows_give_the_uncached_output(small_db, data):
    directory = Path(os.environ["LENSAUDIT_CACHE_DIR"])
    uncached = {f: scan_output([small_db], f, directory, "--no-cache") for f in ("csv", "json")}
    for stale in directory.glob("parsed-*"):
        stale.unlink()
    for output_format in ("csv", "json"):
        scan_output([small_db], output_format, directory)
    path = the_cache_file(directory)
    original = path.read_bytes()
    damaged = flipped(original, data.draw(FLIPS))
    path.write_bytes(damaged)
    for output_format in ("csv", "json"):
        assert scan_output([small_db], output_format, directory) == uncached[output_format]


@pytest.mark.parametrize(
    "module", ["pipeline.py", "formats/csv_format.py", "formats/json_format.py"]
)
def test_the_code_digest_changes_with_the_code_that_renders_rows(tmp_path, module):
    package = tmp_path / "lensaudit"
    shutil.copytree(Path(cache_module.__file__).parent, package)
    before = cache_module._code_digest(package)
    with (package / module).open("a") as stream:
        stream.write("\n# an edit\n")
    assert cache_module._code_digest(package) != before


# --- never stale ------------------------------------------------------------------------


def test_a_changed_file_is_parsed_again(write_xml, cache_dir_path):
    path = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.1"/>'))
    assert [e.focal for e in load_with_cache(path.parent, cache_dir_path).entries] == [10.0]
    path.write_text(
        lens_xml(
            '<distortion model="poly3" focal="12" k1="-0.1"/>',
            '<distortion model="poly3" focal="14" k1="-0.1"/>',
        )
    )
    os.utime(path, ns=(1, 1))  # a different time even on coarse file systems
    assert [e.focal for e in load_with_cache(path.parent, cache_dir_path).entries] == [12.0, 14.0]


def test_a_changed_file_is_audited_again(write_xml):
    path = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.1"/>'))
    assert run(path.parent, cache=True).column("r_max")[0] != math.inf
    run(path.parent, cache=True)
    path.write_text(lens_xml('<distortion model="poly3" focal="10" k1="0.1"/>'))
    os.utime(path, ns=(2, 2))
    assert run(path.parent, cache=True).column("r_max") == [math.inf]


def rewrite_keeping_size_and_time(path: Path, text: str) -> None:
    """Replace a file's content by one of the same size and restore its times, as
    ``git checkout`` or ``rsync -t`` can leave it."""
    before = path.stat()
    assert len(text.encode()) == before.st_size
    path.write_text(text)
    os.utime(path, ns=(before.st_atime_ns, before.st_mtime_ns))
    after = path.stat()
    assert (after.st_size, after.st_mtime_ns) == (before.st_size, before.st_mtime_ns)


def test_a_same_size_edit_with_restored_time_is_audited_again(write_xml):
    path = write_xml(lens_xml(POLY3.format(k1="-0.1")))
    assert run(path.parent, cache=True).column("r_max") == [
        pytest.approx(poly3_r_max(-0.1), rel=1e-12)
    ]
    rewrite_keeping_size_and_time(path, lens_xml(POLY3.format(k1="-0.2")))
    again = run(path.parent, cache=True)
    assert again.column("k1") == [-0.2]
    assert again.column("r_max") == [pytest.approx(math.sqrt(2), rel=1e-12)]


def test_a_same_size_edit_with_restored_time_is_parsed_again(write_xml, cache_dir_path):
    path = write_xml(lens_xml(POLY3.format(k1="-0.1")))
    load_with_cache(path, cache_dir_path)
    rewrite_keeping_size_and_time(path, lens_xml(POLY3.format(k1="-0.3")))
    assert [e.k1 for e in load_with_cache(path, cache_dir_path).entries] == [-0.3]


def test_a_same_size_edit_with_restored_time_is_scanned_again_by_the_cli(write_xml):
    path = write_xml(lens_xml(POLY3.format(k1="-0.1")))
    runner = CliRunner()
    first = runner.invoke(main, ["scan", str(path), "--format", "csv"])
    rewrite_keeping_size_and_time(path, lens_xml(POLY3.format(k1="-0.4")))
    second = runner.invoke(main, ["scan", str(path), "--format", "csv"])
    uncached = runner.invoke(main, ["scan", str(path), "--format", "csv", "--no-cache"])
    assert (first.exit_code, second.exit_code, uncached.exit_code) == (0, 0, 0)
    assert ",-0.4," in second.output and ",-0.1," in first.output
    assert second.output == uncached.output


# --- never trusted when damaged ---------------------------------------------------------


def primed_cache(database: Path, directory: Path) -> tuple[Path, bytes]:
    """Audit ``database`` with an empty cache; the cache file written and its bytes."""
    for stale in directory.glob("parsed-*"):
        stale.unlink()
    run(database, cache=True)
    path = the_cache_file(directory)
    return path, path.read_bytes()


def test_a_corrupt_cache_file_is_ignored(write_xml, cache_dir_path):
    path = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.1"/>'))
    load_with_cache(path.parent, cache_dir_path)
    for file in cache_dir_path.iterdir():
        file.write_bytes(b"\x00garbage")
    assert [e.focal for e in load_with_cache(path.parent, cache_dir_path).entries] == [10.0]


def test_a_flipped_byte_in_the_cache_file_is_detected(small_db, cache_dir_path):
    uncached = snapshot(run(small_db, cache=False))
    path, data = primed_cache(small_db, cache_dir_path)
    # A byte of the stored r_max of a.xml's poly3 entry: a double, read as is if trusted.
    expected = poly3_r_max(-0.1)
    (start,) = [
        start
        for start in range(len(data) - 7)
        if math.isclose(array("d", data[start : start + 8])[0], expected, rel_tol=1e-12)
    ]
    position = start + 6
    path.write_bytes(data[:position] + bytes([data[position] ^ 0x01]) + data[position + 1 :])
    assert snapshot(run(small_db, cache=True)) == uncached


def test_a_truncated_cache_file_is_detected(small_db, cache_dir_path):
    uncached = snapshot(run(small_db, cache=False))
    path, data = primed_cache(small_db, cache_dir_path)
    path.write_bytes(data[: len(data) * 2 // 3])
    assert snapshot(run(small_db, cache=True)) == uncached


@settings(max_examples=150, deadline=None)
@given(st.data())
def test_any_flipped_bytes_in_the_cache_file_give_the_uncached_audit(small_db, data):
    directory = Path(os.environ["LENSAUDIT_CACHE_DIR"])
    uncached = snapshot(run(small_db, cache=False))
    path, original = primed_cache(small_db, directory)
    damaged = flipped(original, data.draw(FLIPS))
    if damaged == original:  # two flips of one byte that cancel out
        return
    path.write_bytes(damaged)
    assert snapshot(run(small_db, cache=True)) == uncached


def parts_of(data: bytes) -> tuple[list, list[bytes]]:
    """The head and the parts of a cache file, read as the documented layout says:
    the header, BLAKE2b-256, the head's length (8 bytes, little-endian), the
    head (marshal data: the head and each part's seal and length), the parts."""
    start = len(store.PARTS_MAGIC) + 32
    length = int.from_bytes(data[start : start + 8], "little")
    head, seals = marshal.loads(data[start + 8 : start + 8 + length])
    parts, position = [], start + 8 + length
    for _, size in seals:
        parts.append(data[position : position + size])
        position += size
    assert position == len(data)
    return head, parts


def signed(head: list, parts: list[bytes], signature_format: bytes, seals=None) -> bytes:
    """A cache file of ``head`` and ``parts``, laid out and signed as documented
    (each part sealed with BLAKE2b-256 of its bytes, unless ``seals`` are given)."""
    if seals is None:
        seals = [hashlib.blake2b(part, digest_size=32).digest() for part in parts]
    body = marshal.dumps(
        (head, [(seal, len(part)) for seal, part in zip(seals, parts, strict=True)])
    )
    signature = hashlib.blake2b(signature_format + body, digest_size=32).digest()
    return store.PARTS_MAGIC + signature + len(body).to_bytes(8, "little") + body + b"".join(parts)


def forged_parts(parts: list[bytes]) -> list[bytes]:
    """The records of ``parts`` with every r_max set to 42 and no rows rendered."""
    forged = []
    for part in parts:
        digest, entries, error, metrics, name, _, tally = marshal.loads(part)
        count = len(array("d", metrics["r_max"]))
        metrics = dict(metrics, r_max=array("d", [42.0] * count).tobytes())
        forged.append(marshal.dumps((digest, entries, error, metrics, name, {}, tally)))
    return forged


def forge(path: Path, data: bytes, signature_format: bytes) -> None:
    """Rewrite the cache file with every r_max set to 42, signed as the documented format
    says for ``signature_format``."""
    head, parts = parts_of(data)
    path.write_bytes(signed(head, forged_parts(parts), signature_format))


def test_a_cache_file_signed_for_this_version_is_served(small_db, cache_dir_path):
    # Shows that the forgery below is what the cache reads when its checksum holds.
    path, data = primed_cache(small_db, cache_dir_path)
    forge(path, data, cache_module.fingerprint())
    assert 42.0 in run(small_db, cache=True).column("r_max")


def test_a_record_that_does_not_match_its_seal_is_not_served(small_db, cache_dir_path):
    uncached = snapshot(run(small_db, cache=False))
    path, data = primed_cache(small_db, cache_dir_path)
    head, parts = parts_of(data)
    old_seals = [hashlib.blake2b(part, digest_size=32).digest() for part in parts]
    # The head signed as it should be, the records changed under their old seals.
    path.write_bytes(signed(head, forged_parts(parts), cache_module.fingerprint(), old_seals))
    assert snapshot(run(small_db, cache=True)) == uncached


def test_one_damaged_record_costs_only_its_file(small_db, cache_dir_path, monkeypatch):
    uncached = snapshot(run(small_db, cache=False))
    path, data = primed_cache(small_db, cache_dir_path)
    head, parts = parts_of(data)
    seals = [hashlib.blake2b(part, digest_size=32).digest() for part in parts]
    damaged = bytes([parts[0][0] ^ 1]) + parts[0][1:]
    path.write_bytes(signed(head, [damaged, *parts[1:]], cache_module.fingerprint(), seals))
    calls = count_parses(monkeypatch)
    assert snapshot(run(small_db, cache=True)) == uncached
    assert len(calls) == 1 and len(parts) == 3


def test_a_cache_file_from_another_version_is_ignored(small_db, cache_dir_path):
    uncached = snapshot(run(small_db, cache=False))
    path, data = primed_cache(small_db, cache_dir_path)
    forge(path, data, b"an older version: " + cache_module.fingerprint())
    assert snapshot(run(small_db, cache=True)) == uncached


def test_a_cache_file_of_the_previous_layout_is_ignored(small_db, cache_dir_path):
    uncached = snapshot(run(small_db, cache=False))
    path, _ = primed_cache(small_db, cache_dir_path)
    path.write_bytes(marshal.dumps(("lensaudit-cache 3 0.1.0", {})))
    assert snapshot(run(small_db, cache=True)) == uncached


def test_a_directory_in_place_of_the_cache_file_only_costs_speed(small_db, cache_dir_path):
    uncached = snapshot(run(small_db, cache=False))
    path, _ = primed_cache(small_db, cache_dir_path)
    path.unlink()
    path.mkdir()
    assert snapshot(run(small_db, cache=True)) == uncached
    assert snapshot(run(small_db, cache=True)) == uncached


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes on this system")
def test_a_fifo_in_place_of_the_cache_file_does_not_hang(small_db, cache_dir_path):
    uncached = snapshot(run(small_db, cache=False))
    path, _ = primed_cache(small_db, cache_dir_path)
    path.unlink()
    os.mkfifo(path)
    outcome = []
    worker = threading.Thread(target=lambda: outcome.append(run(small_db, cache=True)), daemon=True)
    worker.start()
    worker.join(timeout=30)
    assert not worker.is_alive() and snapshot(outcome[0]) == uncached


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes on this system")
def test_a_cached_file_replaced_by_a_fifo_does_not_hang(write_xml):
    path = write_xml(lens_xml(POLY3.format(k1="-0.1")))
    run(path.parent, cache=True)
    path.unlink()
    os.mkfifo(path)
    outcome = []
    worker = threading.Thread(
        target=lambda: outcome.append(run(path.parent, cache=True)), daemon=True
    )
    worker.start()
    worker.join(timeout=30)
    assert not worker.is_alive()
    assert snapshot(outcome[0]) == snapshot(run(path.parent, cache=False))
    assert outcome[0].column("status") == ["unreadable"]


def test_an_unwritable_cache_directory_only_costs_speed(write_xml, tmp_path, monkeypatch):
    blocker = tmp_path / "not-a-directory"
    blocker.write_text("")
    monkeypatch.setenv("LENSAUDIT_CACHE_DIR", str(blocker / "cache"))
    path = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.1"/>'))
    assert len(run(path.parent, cache=True)) == 1


@pytest.mark.skipif(sys.platform == "win32", reason="file size limits are POSIX")
def test_a_full_disk_only_costs_speed(small_db, cache_dir_path):
    # Writes beyond 100 bytes fail (EFBIG), as they would on a full disk.
    limited = (
        "import resource, runpy, sys\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (100, 100))\n"
        "sys.argv[0] = 'lensaudit'\n"
        "runpy.run_module('lensaudit', run_name='__main__')\n"
    )
    arguments = ["scan", str(small_db), "--format", "csv"]
    env = dict(os.environ, LENSAUDIT_CACHE_DIR=str(cache_dir_path))
    full = subprocess.run(
        [sys.executable, "-c", limited, *arguments], env=env, capture_output=True, text=True
    )
    uncached = subprocess.run(
        [sys.executable, "-m", "lensaudit", *arguments, "--no-cache"],
        env=env,
        capture_output=True,
        text=True,
    )
    assert (full.returncode, full.stderr, full.stdout) == (0, "", uncached.stdout)
    assert list(cache_dir_path.iterdir()) == []  # no partial or temporary file left


# --- bounded ----------------------------------------------------------------------------


def one_file_databases(directory: Path, count: int) -> list[Path]:
    """``count`` one-entry files of equal size, each audited alone (one cache file each)."""
    directory.mkdir()
    paths = []
    for index in range(count):
        path = directory / f"{index}.xml"
        path.write_text(lens_xml(POLY3.format(k1="-0.1")))
        paths.append(path)
    return paths


def audit_alone(path: Path, directory: Path) -> Path:
    """Audit one file with the cache; the cache file it uses."""
    before = set(cache_files(directory))
    run(path, cache=True)
    return (set(cache_files(directory)) - before).pop() if before else cache_files(directory)[0]


def test_the_least_recently_used_cache_files_are_evicted(tmp_path, cache_dir_path, monkeypatch):
    monkeypatch.setattr(cache_module, "MAX_CACHE_FILES", 3)
    a, b, c, d = one_file_databases(tmp_path / "dbs", 4)
    used = {}
    for age, path in zip((3000, 2000, 1000), (a, b, c), strict=True):
        used[path] = audit_alone(path, cache_dir_path)
        os.utime(used[path], (time.time() - age, time.time() - age))
    run(a, cache=True)  # the oldest, used again: b is now the least recently used
    used[d] = audit_alone(d, cache_dir_path)
    assert set(cache_files(cache_dir_path)) == {used[a], used[c], used[d]}


def test_cache_files_beyond_the_byte_limit_are_evicted(tmp_path, cache_dir_path, monkeypatch):
    a, b, c = one_file_databases(tmp_path / "dbs", 3)
    used = {}
    for age, path in zip((2000, 1000), (a, b), strict=True):
        used[path] = audit_alone(path, cache_dir_path)
        os.utime(used[path], (time.time() - age, time.time() - age))
    size = used[a].stat().st_size
    assert used[b].stat().st_size == size
    monkeypatch.setattr(cache_module, "MAX_CACHE_BYTES", 2 * size + size // 2)
    used[c] = audit_alone(c, cache_dir_path)
    assert set(cache_files(cache_dir_path)) == {used[b], used[c]}


def test_abandoned_temporary_files_are_removed_and_others_kept(small_db, cache_dir_path):
    cache_dir_path.mkdir()
    abandoned = cache_dir_path / "parsed-abandoned.tmp"
    in_progress = cache_dir_path / "parsed-in-progress.tmp"
    history = cache_dir_path / "history-0.1.0-0123456789abcdef.sqlite3"
    for path in (abandoned, in_progress, history):
        path.write_bytes(b"x")
    old = time.time() - 2 * 3600
    os.utime(abandoned, (old, old))
    os.utime(history, (old, old))
    run(small_db, cache=True)
    assert not abandoned.exists() and in_progress.exists() and history.exists()


def test_records_of_files_no_longer_scanned_are_dropped(write_xml, cache_dir_path, monkeypatch):
    a = write_xml(lens_xml(POLY3.format(k1="-0.1")), "a.xml").resolve()
    b = write_xml(lens_xml(POLY3.format(k1="-0.2")), "b.xml").resolve()

    def load(targets):
        cache = ParseCache([a, b], cache_dir_path)
        loader.load_files(targets, cache)
        cache.save()

    load([(a, "a.xml"), (b, "b.xml")])
    load([(a, "a.xml")])  # b is not seen: its record goes
    calls = count_parses(monkeypatch)
    load([(a, "a.xml"), (b, "b.xml")])
    assert calls == ["b.xml"]


# --- file names and where the cache is ---------------------------------------------------


def test_a_file_name_that_is_not_utf8_is_scanned_with_and_without_cache(tmp_path):
    directory = tmp_path / "db"
    directory.mkdir()
    name = os.fsdecode(b"caf\xff.xml")
    try:
        (directory / name).write_text(lens_xml(POLY3.format(k1="-0.1")))
    except (OSError, UnicodeError):
        pytest.skip("this file system does not take file names that are not UTF-8")
    runner = CliRunner()
    scans = [
        runner.invoke(main, ["scan", str(directory), "--format", "csv", *option])
        for option in (["--no-cache"], [], [])  # no cache, then a cold and a warm cache
    ]
    assert [scan.exit_code for scan in scans] == [0, 0, 0], [s.output for s in scans]
    assert scans[0].output.count("\n") == 2 and ",-0.1," in scans[0].output
    assert scans[1].output == scans[0].output and scans[2].output == scans[0].output


def test_a_file_name_that_is_not_utf8_is_kept_in_the_cache(tmp_path, monkeypatch):
    path = tmp_path / os.fsdecode(b"caf\xff.xml")
    try:
        path.write_text(lens_xml(POLY3.format(k1="-0.1")))
    except (OSError, UnicodeError):
        pytest.skip("this file system does not take file names that are not UTF-8")
    run(path, cache=True)
    calls = count_parses(monkeypatch)
    assert run(path, cache=True).column("k1") == [-0.1] and calls == []


def test_the_cache_is_written_to_lensaudit_cache_dir(small_db, tmp_path, monkeypatch):
    monkeypatch.setenv("LENSAUDIT_CACHE_DIR", str(tmp_path / "explicit"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    run(small_db, cache=True)
    assert len(cache_files(tmp_path / "explicit")) == 1
    assert not (tmp_path / "xdg").exists()


def test_the_cache_is_written_to_xdg_cache_home_without_lensaudit_cache_dir(
    small_db, tmp_path, monkeypatch
):
    monkeypatch.delenv("LENSAUDIT_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    run(small_db, cache=True)
    assert len(cache_files(tmp_path / "xdg" / "lensaudit")) == 1


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
