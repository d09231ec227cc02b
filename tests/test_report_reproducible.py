"""Two reports of the same database are the same bytes; only report.html carries a date."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

from lensaudit.report import REPORT_FILES, audit, write_report

# 2021-05-30 and 2024-02-29, 12:00 UTC.
EPOCHS = ("1622376000", "1709208000")
GENERATED = re.compile(r"<dt>Generated</dt><dd>[^<]*</dd>")


@pytest.fixture(scope="module")
def two_reports(bundled_db, tmp_path_factory):
    """The bundled database's report written twice, from two audits, on two dates."""
    directories = []
    with pytest.MonkeyPatch.context() as patch:
        for epoch in EPOCHS:
            patch.setenv("SOURCE_DATE_EPOCH", epoch)
            out = tmp_path_factory.mktemp(f"report-{epoch}")
            write_report(audit(bundled_db), out)
            directories.append(out)
    return directories


def test_figure5_csv_is_the_same_bytes_in_two_runs(two_reports):
    first, second = (d / "fig5_r_normalized.csv" for d in two_reports)
    assert first.read_bytes() == second.read_bytes()
    assert first.read_bytes().count(b"\n") > 10


@pytest.mark.parametrize("name", [n for n in REPORT_FILES if n != "report.html"])
def test_every_other_report_file_is_the_same_bytes_on_another_day(two_reports, name):
    first, second = (d / name for d in two_reports)
    assert first.read_bytes() == second.read_bytes()


def test_report_html_differs_only_in_its_date(two_reports):
    first, second = (d.joinpath("report.html").read_text("utf-8") for d in two_reports)
    assert first != second
    dates = [GENERATED.findall(page) for page in (first, second)]
    assert dates == [
        ["<dt>Generated</dt><dd>2021-05-30T12:00:00Z</dd>"],
        ["<dt>Generated</dt><dd>2024-02-29T12:00:00Z</dd>"],
    ]
    assert GENERATED.sub("", first) == GENERATED.sub("", second)


def test_summary_json_carries_no_date(two_reports):
    text = two_reports[0].joinpath("summary.json").read_text("utf-8")
    assert not re.search(r"\d{4}-\d\d-\d\dT\d\d:\d\d", text)


def test_fresh_processes_with_other_hash_seeds_and_caches_write_the_same_bytes(tmp_path):
    """Set ordering (hash seeds), a cold or warm parse cache and the process itself
    must not show in the output."""
    outputs = []
    cache = tmp_path / "cache"
    for seed in ("1", "2", "3"):
        out = tmp_path / f"out-{seed}"
        environment = {
            **os.environ,
            "PYTHONHASHSEED": seed,
            "SOURCE_DATE_EPOCH": EPOCHS[0],
            "LENSAUDIT_CACHE_DIR": str(cache),  # cold for the first run, warm after
        }
        result = subprocess.run(
            [sys.executable, "-m", "lensaudit", "report", "-o", str(out)],
            env=environment,
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
        )
        assert result.returncode == 0, result.stderr[-2000:]
        outputs.append({name: (out / name).read_bytes() for name in REPORT_FILES})
    assert outputs[0] == outputs[1] == outputs[2]


def test_the_command_writes_what_the_library_writes(bundled_db, two_reports, tmp_path):
    """The command draws Figure 5 in a process of its own where it can
    (lensaudit.report.drawing), write_report here: the same bytes."""
    out = tmp_path / "out"
    result = subprocess.run(
        [sys.executable, "-m", "lensaudit", "report", str(bundled_db), "-o", str(out)],
        env={**os.environ, "SOURCE_DATE_EPOCH": EPOCHS[0]},
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    for name in REPORT_FILES:
        assert (out / name).read_bytes() == (two_reports[0] / name).read_bytes(), name
