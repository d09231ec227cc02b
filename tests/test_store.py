"""The store under lensaudit's caches: a value comes back only as written, damage
reads as no file, writes are whole, and store files of every kind share one bound."""

from __future__ import annotations

import hashlib
import marshal
import os
import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from damage import FLIPS, flipped
from lensaudit import store

FINGERPRINT = b"test format 1"
VALUE = {"a": (1, 2.5, "text"), "b": [b"\x00\x01", None, True]}


def record_file(
    directory: Path, kind: str = "parsed", name: str = "x", **bounds
) -> store.RecordFile:
    limits = {"max_files": 16, "max_bytes": 1 << 20} | bounds
    return store.RecordFile(directory, kind, name, FINGERPRINT, **limits)


def test_a_value_written_is_read_back_equal(tmp_path):
    file = record_file(tmp_path)
    file.write(VALUE)
    assert record_file(tmp_path).read() == VALUE


def test_the_file_is_named_after_its_kind_and_name(tmp_path):
    file = record_file(tmp_path, "history", "blobs")
    file.write(VALUE)
    assert [p.name for p in tmp_path.iterdir()] == ["history-blobs.cache"]


def test_a_missing_file_reads_as_none(tmp_path):
    assert record_file(tmp_path).read() is None


def test_the_file_is_the_documented_header_checksum_and_marshal_data(tmp_path):
    file = record_file(tmp_path)
    file.write(VALUE)
    data = file.path.read_bytes()
    body = marshal.dumps(VALUE)
    expected = hashlib.blake2b(FINGERPRINT + body, digest_size=32).digest()
    assert data == store.MAGIC + expected + body


def test_a_file_of_another_fingerprint_reads_as_none(tmp_path):
    record_file(tmp_path).write(VALUE)
    other = store.RecordFile(
        tmp_path, "parsed", "x", b"test format 2", max_files=16, max_bytes=1 << 20
    )
    assert other.read() is None


def written(directory: Path) -> tuple[store.RecordFile, bytes]:
    """A store file holding VALUE, and its bytes."""
    file = record_file(directory)
    file.write(VALUE)
    return file, file.path.read_bytes()


def damaged(write, directory: Path, flips) -> store.RecordFile | None:
    """A store file made by ``write`` with ``flips`` applied; None if they cancel out."""
    file, original = write(directory)
    changed = flipped(original, flips)
    if changed == original:
        return None
    file.path.write_bytes(changed)
    return file


@settings(max_examples=200, deadline=None)
@given(flips=FLIPS)
def test_any_flipped_bytes_read_as_none(tmp_path_factory, flips):
    file = damaged(written, tmp_path_factory.mktemp("store"), flips)
    assert file is None or file.read() is None


HEAD = [("a", 1), ("b", 2)]
PARTS_VALUES = [{"x": [1.5, "text"]}, (b"\x00" * 1000, None, True)]


def written_parts(directory: Path) -> tuple[store.RecordFile, bytes]:
    """A store file holding HEAD and PARTS_VALUES as sealed parts, and its bytes."""
    file = record_file(directory)
    file.write_parts(HEAD, [store.sealed(value) for value in PARTS_VALUES])
    return file, file.path.read_bytes()


def values_read(file: store.RecordFile):
    """The head and the values of the parts read back, None for a part that fails its seal."""
    found = file.read_parts()
    if found is None:
        return None
    head, parts = found
    return head, [store.unseal(seal, body) for seal, body in parts]


def test_parts_written_are_read_back_equal(tmp_path):
    file, _ = written_parts(tmp_path)
    assert values_read(record_file(tmp_path)) == (HEAD, PARTS_VALUES)


def test_a_file_of_parts_is_the_documented_layout(tmp_path):
    _, data = written_parts(tmp_path)
    parts = [marshal.dumps(value) for value in PARTS_VALUES]
    seals = [hashlib.blake2b(part, digest_size=32).digest() for part in parts]
    head = marshal.dumps(
        (HEAD, [(seal, len(part)) for seal, part in zip(seals, parts, strict=True)])
    )
    checksum = hashlib.blake2b(FINGERPRINT + head, digest_size=32).digest()
    layout = store.PARTS_MAGIC + checksum + len(head).to_bytes(8, "little") + head
    assert data == layout + b"".join(parts)


def test_a_file_of_parts_is_not_read_as_one_value_nor_the_reverse(tmp_path):
    written_parts(tmp_path)
    assert record_file(tmp_path).read() is None
    record_file(tmp_path).write(VALUE)
    assert record_file(tmp_path).read_parts() is None


def test_parts_of_another_fingerprint_read_as_none(tmp_path):
    written_parts(tmp_path)
    other = store.RecordFile(
        tmp_path, "parsed", "x", b"test format 2", max_files=16, max_bytes=1 << 20
    )
    assert other.read_parts() is None


@settings(max_examples=200, deadline=None)
@given(flips=FLIPS)
def test_flipped_bytes_in_a_file_of_parts_never_give_another_value(tmp_path_factory, flips):
    file = damaged(written_parts, tmp_path_factory.mktemp("store"), flips)
    if file is None:
        return
    found = values_read(file)
    # The head damaged: nothing; a part damaged: that part fails its seal.
    assert found is None or (
        found[0] == HEAD
        and all(
            value in (None, expected)
            for value, expected in zip(found[1], PARTS_VALUES, strict=True)
        )
        and None in found[1]
    )


@pytest.mark.parametrize("layout", ["one value", "parts"])
@settings(max_examples=100, deadline=None)
@given(st.data())
def test_any_truncation_reads_as_none(tmp_path_factory, layout, data):
    write, read = (written, "read") if layout == "one value" else (written_parts, "read_parts")
    file, original = write(tmp_path_factory.mktemp("store"))
    file.path.write_bytes(original[: data.draw(st.integers(0, len(original) - 1))])
    assert getattr(file, read)() is None


def test_parts_larger_than_the_bound_are_not_written(tmp_path):
    small = record_file(tmp_path, max_bytes=500)
    with pytest.raises(ValueError):
        small.write_parts(HEAD, [store.sealed(value) for value in PARTS_VALUES])
    assert not small.path.exists()


def test_a_file_larger_than_the_bound_is_neither_written_nor_read(tmp_path):
    small = record_file(tmp_path, max_bytes=100)
    with pytest.raises(ValueError):
        small.write(b"x" * 200)
    assert not small.path.exists()
    record_file(tmp_path).write(b"x" * 200)
    assert small.read() is None


def test_a_directory_in_place_of_the_file_reads_as_none_and_fails_to_write(tmp_path):
    file = record_file(tmp_path)
    file.path.mkdir()
    assert file.read() is None
    with pytest.raises(OSError):
        file.write(VALUE)
    assert [p.name for p in tmp_path.iterdir()] == [file.path.name]  # no temporary file left


def test_an_unknown_kind_is_refused(tmp_path):
    with pytest.raises(ValueError):
        record_file(tmp_path, "other")


def aged(path: Path, seconds: float) -> None:
    then = time.time() - seconds
    os.utime(path, (then, then))


def test_eviction_counts_store_files_of_every_kind(tmp_path):
    oldest = record_file(tmp_path, "history", "blobs")
    older = record_file(tmp_path, "parsed", "a")
    for age, file in ((3000, oldest), (2000, older)):
        file.write(VALUE)
        aged(file.path, age)
    record_file(tmp_path, "parsed", "b", max_files=2).write(VALUE)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["parsed-a.cache", "parsed-b.cache"]


def test_eviction_by_size_removes_the_least_recently_used(tmp_path):
    files = [record_file(tmp_path, "history", name) for name in ("run", "blobs")]
    for age, file in zip((1000, 2000), files, strict=True):
        file.write(VALUE)
        aged(file.path, age)
    size = files[0].path.stat().st_size
    record_file(tmp_path, "parsed", "c", max_bytes=2 * size + size // 2).write(VALUE)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["history-run.cache", "parsed-c.cache"]


def test_reading_a_file_keeps_it_from_eviction(tmp_path):
    first, second = record_file(tmp_path, "parsed", "a"), record_file(tmp_path, "parsed", "b")
    for age, file in ((2000, first), (1000, second)):
        file.write(VALUE)
        aged(file.path, age)
    assert first.read() == VALUE  # now the most recently used
    record_file(tmp_path, "history", "run", max_files=2).write(VALUE)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["history-run.cache", "parsed-a.cache"]


def test_eviction_leaves_files_that_are_not_store_files(tmp_path):
    others = [tmp_path / name for name in ("notes.cache", "other-x.cache", "history-trend-a.png")]
    for path in others:
        path.write_bytes(b"x")
        aged(path, 5000)
    record_file(tmp_path, "parsed", "a", max_files=1).write(VALUE)
    assert all(path.exists() for path in others)


def test_abandoned_temporary_files_are_removed_and_recent_ones_kept(tmp_path):
    abandoned, recent = tmp_path / "history-0123.tmp", tmp_path / "parsed-4567.tmp"
    for path in (abandoned, recent):
        path.write_bytes(b"x")
    aged(abandoned, 2 * 3600)
    record_file(tmp_path).write(VALUE)
    assert not abandoned.exists() and recent.exists()
