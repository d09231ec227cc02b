"""The parse cache: same entries as a fresh parse, and never stale."""

from __future__ import annotations

import math
import os
from dataclasses import astuple

import pytest

from conftest import lens_xml
from lensaudit import loader
from lensaudit.cache import ParseCache
from lensaudit.pipeline import run


def normalized(entries):
    return [
        tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in astuple(e))
        for e in entries
    ]


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    directory = tmp_path / "cache"
    monkeypatch.setenv("LENSAUDIT_CACHE_DIR", str(directory))
    return directory


def load_with_cache(paths, directory):
    targets = loader.expand(paths)
    cache = ParseCache([path for path, _ in targets], directory)
    result = loader.load_files(targets, cache)
    cache.save()
    return result


def test_cached_entries_equal_a_fresh_parse_of_the_bundled_database(bundled_db, cache_dir):
    fresh = loader.load(bundled_db)
    load_with_cache(bundled_db, cache_dir)
    assert any(cache_dir.iterdir())
    cached = load_with_cache(bundled_db, cache_dir)
    assert normalized(cached.entries) == normalized(fresh.entries)
    assert [f.name for f in cached.files] == [f.name for f in fresh.files]


def test_a_changed_file_is_parsed_again(write_xml, cache_dir):
    path = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.1"/>'))
    assert [e.focal for e in load_with_cache(path.parent, cache_dir).entries] == [10.0]
    path.write_text(
        lens_xml(
            '<distortion model="poly3" focal="12" k1="-0.1"/>',
            '<distortion model="poly3" focal="14" k1="-0.1"/>',
        )
    )
    os.utime(path, ns=(1, 1))  # a different time even on coarse file systems
    assert [e.focal for e in load_with_cache(path.parent, cache_dir).entries] == [12.0, 14.0]


def test_broken_files_and_statuses_survive_the_cache(write_xml, cache_dir):
    write_xml("<lensdatabase><lens>", "broken.xml")
    directory = write_xml(
        lens_xml('<distortion model="acm" focal="10" k1="1"/>'), "other.xml"
    ).parent
    fresh = loader.load(directory)
    load_with_cache(directory, cache_dir)
    cached = load_with_cache(directory, cache_dir)
    assert normalized(cached.entries) == normalized(fresh.entries)
    assert [f.error for f in cached.files] == [f.error for f in fresh.files]
    assert {e.status for e in cached.entries} == {"xml_error", "unknown_model"}


def test_a_corrupt_cache_file_is_ignored(write_xml, cache_dir):
    path = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.1"/>'))
    load_with_cache(path.parent, cache_dir)
    for file in cache_dir.iterdir():
        file.write_bytes(b"\x00garbage")
    assert [e.focal for e in load_with_cache(path.parent, cache_dir).entries] == [10.0]


def test_an_unwritable_cache_directory_only_costs_speed(write_xml, tmp_path, monkeypatch):
    blocker = tmp_path / "not-a-directory"
    blocker.write_text("")
    monkeypatch.setenv("LENSAUDIT_CACHE_DIR", str(blocker / "cache"))
    path = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.1"/>'))
    assert len(run(path.parent, cache=True)) == 1


def test_a_warm_audit_gives_the_same_columns_as_a_cold_one(bundled_db, cache_dir):
    cold = run(bundled_db, cache=False)
    run(bundled_db, cache=True)  # fills the cache
    warm = run(bundled_db, cache=True)
    assert warm._metric_columns is not None and "metrics" not in warm.__dict__  # from the cache
    for name, values in cold.columns().items():
        assert [("nan" if v != v else v) for v in warm.column(name)] == [
            ("nan" if v != v else v) for v in values
        ], name
    assert warm.summary.to_dict() == cold.summary.to_dict()


def test_a_changed_file_is_audited_again(write_xml, cache_dir):
    path = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.1"/>'))
    assert run(path.parent, cache=True).column("r_max")[0] != math.inf
    run(path.parent, cache=True)
    path.write_text(lens_xml('<distortion model="poly3" focal="10" k1="0.1"/>'))
    os.utime(path, ns=(2, 2))
    assert run(path.parent, cache=True).column("r_max") == [math.inf]


def test_scan_from_a_warm_cache_does_not_import_numpy(tmp_path, cache_dir):
    import subprocess
    import sys

    script = (
        "import io, sys\n"
        "from lensaudit.pipeline import run\n"
        "from lensaudit.formats import writer\n"
        "writer('csv')(run(cache=True), io.StringIO())\n"
        "print('numpy' in sys.modules)\n"
    )
    env = dict(os.environ, LENSAUDIT_CACHE_DIR=str(cache_dir))
    first = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True
    )
    second = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, check=True
    )
    assert (first.stdout.strip(), second.stdout.strip()) == ("True", "False")
