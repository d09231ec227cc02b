"""`lensaudit scan`: outputs, columns, exit codes."""

from __future__ import annotations

import csv
import io
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import lens_xml
from lensaudit.cli import main
from lensaudit.columns import METRIC_FLOAT_COLUMNS, format_floats
from lensaudit.formats import json_format, writer
from lensaudit.pipeline import COLUMNS, Audit, run
from lensaudit.read import DatabaseSource, DistortionEntry, SourceFile

EXPECTED_HEADER = (
    "file,line,maker,lens,type,crop_factor,aspect_ratio,model,focal,real_focal,"
    "a,b,c,k1,k2,r_max,d_max,tail,r_corner,r_normalized,r_corner_paper,"
    "r_normalized_paper,folds_in_image,status,message"
)


@pytest.fixture
def runner():
    return CliRunner()


@pytest.fixture
def small_db(write_xml):
    path = write_xml(
        lens_xml(
            '<distortion model="poly3" focal="10" k1="-0.3"/>',
            '<distortion model="poly3" focal="20" k1="0.01"/>',
            '<distortion model="acm" focal="30" k1="0.01"/>',
            '<distortion model="ptlens" focal="40" a="x"/>',
        )
    )
    return path.parent


def test_csv_header_is_the_documented_columns(runner, small_db):
    result = runner.invoke(main, ["scan", str(small_db), "--format", "csv"])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines()[0] == EXPECTED_HEADER
    assert ",".join(COLUMNS) == EXPECTED_HEADER


def test_every_entry_appears_in_csv_with_status(runner, small_db):
    result = runner.invoke(main, ["scan", str(small_db), "-f", "csv"])
    rows = list(csv.DictReader(io.StringIO(result.output)))
    assert [(r["focal"], r["status"]) for r in rows] == [
        ("10.0", "ok"),
        ("20.0", "ok"),
        ("30.0", "unknown_model"),
        ("40.0", "bad_value"),
    ]
    assert rows[0]["folds_in_image"] == "true" and rows[0]["tail"] == "negative"
    assert (
        rows[1]["r_max"] == "inf" and rows[1]["tail"] == "" and rows[1]["folds_in_image"] == "false"
    )
    assert rows[2]["r_max"] == "" and rows[2]["folds_in_image"] == ""
    assert rows[0]["file"] == "test.xml" and int(rows[0]["line"]) == 10


def test_csv_floats_round_trip(runner, small_db):
    result = runner.invoke(main, ["scan", str(small_db), "-f", "csv"])
    row = next(csv.DictReader(io.StringIO(result.output)))
    k1 = -0.3
    expected = math.sqrt((1 - k1) / (-3 * k1))
    assert float(row["r_max"]) == pytest.approx(expected, rel=1e-14)


def test_json_has_entries_and_summary(runner, small_db):
    result = runner.invoke(main, ["scan", str(small_db), "-f", "json"])
    document = json.loads(result.output)
    assert [list(e) for e in document["entries"]] == [list(COLUMNS)] * 4
    assert document["entries"][1]["r_max"] == "inf"
    total = document["summary"]["table1"][-1]
    assert (total["model"], total["finite"], total["infinite"], total["total"]) == (
        "Total",
        1,
        1,
        2,
    )
    assert document["summary"]["statuses"] == {"ok": 2, "bad_value": 1, "unknown_model": 1}


def test_table_names_the_database_and_lists_folding_entries(runner, small_db):
    result = runner.invoke(main, ["scan", str(small_db)])
    assert result.exit_code == 0
    assert str(small_db) in result.output.splitlines()[0]
    assert "Table 1" in result.output and "Table 2" in result.output
    assert "test.xml:10" in result.output
    assert "Not audited: 2 entries" in result.output


def test_output_file_option_writes_the_file(runner, small_db, tmp_path):
    target = tmp_path / "out.csv"
    result = runner.invoke(main, ["scan", str(small_db), "-f", "csv", "-o", str(target)])
    assert result.exit_code == 0 and result.output == ""
    assert target.read_text().splitlines()[0] == EXPECTED_HEADER


def test_missing_path_exits_2_with_one_line(runner, tmp_path):
    result = runner.invoke(main, ["scan", str(tmp_path / "missing")])
    assert result.exit_code == 2
    assert result.output.strip().count("\n") == 0 and "no such file" in result.output
    assert "Traceback" not in result.output


def test_unknown_format_is_a_usage_error(runner, small_db):
    result = runner.invoke(main, ["scan", str(small_db), "-f", "xls"])
    assert result.exit_code == 2


def test_only_unreadable_files_exit_2(runner, write_xml):
    path = write_xml("<lensdatabase>", "broken.xml")
    result = runner.invoke(main, ["scan", str(path)])
    assert result.exit_code == 2 and "broken.xml" in result.output


def test_default_is_the_bundled_database(runner, bundled_db):
    result = runner.invoke(main, ["scan"])
    assert result.exit_code == 0
    assert "bundled with lensfunpy" in result.output.splitlines()[0]
    assert str(bundled_db) in result.output.splitlines()[0]


# --- scan --kind vignetting | tca ------------------------------------------

VIGNETTING_HEADER = (
    "file,line,maker,lens,type,crop_factor,aspect_ratio,model,focal,aperture,distance,"
    "k1,k2,k3,r_corner,r_zero,c_min,r_min,c_max,r_cmax,r_turn,zero_in_image,low_in_image,"
    "brightens,monotone,severity,status,message"
)
TCA_HEADER = (
    "file,line,maker,lens,type,crop_factor,aspect_ratio,model,focal,kr,kb,vr,vb,cr,cb,br,bb,"
    "r_corner,r_fold_red,r_fold_blue,folds_in_image,severity,status,message"
)


@pytest.fixture
def calibration_db(write_xml):
    path = write_xml(
        lens_xml(
            '<distortion model="poly3" focal="10" k1="-0.01"/>',
            '<vignetting model="pa" focal="10" aperture="4" distance="10" k1="-1.2" k2="0.1"/>',
            '<vignetting model="pa" focal="10" aperture="8" distance="10" k1="-0.3"/>',
            '<vignetting model="pa" focal="10" aperture="11" distance="10" k1="x"/>',
            '<tca model="poly3" focal="10" vr="1" br="-0.2" vb="1.0001"/>',
            '<tca model="linear" focal="20" kr="1.0001" kb="0.9999"/>',
        )
    )
    return path.parent


def test_kind_vignetting_csv_header_is_the_documented_columns(runner, calibration_db):
    result = runner.invoke(main, ["scan", str(calibration_db), "--kind", "vignetting", "-f", "csv"])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines()[0] == VIGNETTING_HEADER


def test_kind_tca_csv_header_is_the_documented_columns(runner, calibration_db):
    result = runner.invoke(main, ["scan", str(calibration_db), "--kind", "tca", "-f", "csv"])
    assert result.exit_code == 0, result.output
    assert result.output.splitlines()[0] == TCA_HEADER


def test_kind_vignetting_lists_every_entry_with_its_status_and_severity(runner, calibration_db):
    result = runner.invoke(main, ["scan", str(calibration_db), "-k", "vignetting", "-f", "csv"])
    rows = list(csv.DictReader(io.StringIO(result.output)))
    assert [(r["aperture"], r["status"], r["severity"]) for r in rows] == [
        ("4.0", "ok", "error"),
        ("8.0", "ok", ""),
        ("11.0", "bad_value", ""),
    ]
    assert rows[0]["zero_in_image"] == "true" and rows[1]["monotone"] == "true"
    assert rows[2]["zero_in_image"] == "" and rows[2]["c_min"] == ""
    assert float(rows[1]["c_min"]) == 0.7
    assert float(rows[1]["r_zero"]) == pytest.approx(math.sqrt(1 / 0.3), rel=1e-15)


def test_kind_tca_json_is_strict_and_has_every_entry(runner, calibration_db):
    result = runner.invoke(main, ["scan", str(calibration_db), "-k", "tca", "-f", "json"])
    document = json.loads(result.output)
    assert document["kind"] == "tca"
    entries = document["entries"]
    assert [(e["model"], e["folds_in_image"], e["severity"]) for e in entries] == [
        ("poly3", True, "error"),
        ("linear", False, ""),
    ]
    assert entries[1]["r_fold_red"] == "inf" and entries[1]["vr"] is None
    assert document["summary"]["folds_in_image"] == 1


def test_kind_vignetting_table_names_the_entries_below_a_tenth(runner, calibration_db):
    result = runner.invoke(main, ["scan", str(calibration_db), "-k", "vignetting"])
    assert result.exit_code == 0, result.output
    assert "3 vignetting entries, 2 audited" in result.output
    assert "test.xml:11" in result.output  # the C <= 0 entry, by file and line
    assert "Not audited: 1 entries (1 bad_value)" in result.output


def test_kind_distortion_is_the_default_and_unchanged(runner, calibration_db):
    plain = runner.invoke(main, ["scan", str(calibration_db), "-f", "csv", "--no-cache"])
    named = runner.invoke(
        main, ["scan", str(calibration_db), "-f", "csv", "--no-cache", "-k", "distortion"]
    )
    assert plain.exit_code == named.exit_code == 0
    assert plain.output == named.output
    assert plain.output.splitlines()[0] == EXPECTED_HEADER


@pytest.mark.parametrize("kind", ["vignetting", "tca"])
def test_kind_with_a_missing_path_exits_2_with_one_line(runner, tmp_path, kind):
    result = runner.invoke(main, ["scan", str(tmp_path / "nowhere"), "-k", kind])
    assert result.exit_code == 2
    assert result.output.count("\n") == 1 and "no such file" in result.output


def test_kind_with_only_broken_files_exits_2(runner, write_xml):
    path = write_xml(b"\xff\xfe not xml")
    result = runner.invoke(main, ["scan", str(path), "-k", "vignetting"])
    assert result.exit_code == 2
    assert "no file could be read" in result.output


def test_a_distortion_scan_does_no_vignetting_or_tca_work(tmp_path):
    probe = (
        "import os, sys\n"
        "from lensaudit.cli import main\n"
        "sys.argv = ['lensaudit', 'scan', '-f', 'csv', '-o', os.devnull]\n"
        "try:\n    main()\nexcept SystemExit:\n    pass\n"
        "print(sorted(m for m in sys.modules if m.split('.')[-1] in "
        "('calibrations', 'vignetting', 'tca')))\n"
    )
    environment = dict(os.environ, LENSAUDIT_CACHE_DIR=str(tmp_path / "cache"))
    result = subprocess.run(
        [sys.executable, "-c", probe], capture_output=True, text=True, env=environment
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"


# --- the writers render rows column by column and file by file: the same text as
# --- writing every record with the csv and json modules ----------------------------------

# Texts as XML can hold them (no NUL, no lone surrogate), with the characters
# that need quoting or escaping in CSV and JSON.
xml_texts = st.text(
    alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="\0"),
    max_size=8,
) | st.sampled_from(["", "ok", 'a "b", c', "line\nbreak", "cr\rhere", "Zeiß", "ü\u2028"])
any_floats = st.floats(allow_nan=True, allow_infinity=True)


SOME_PROBLEMS = st.sampled_from(["ok", "ok", "bad_value", "xml_error"])


@st.composite
def audits(draw, statuses=SOME_PROBLEMS) -> Audit:
    """An audit of 0 to 3 files of 0 to 3 entries each, with any metrics, held either
    as entries or as packed columns per file (the two forms the writers meet)."""
    files, per_file = [], []
    for number in range(draw(st.integers(0, 3))):
        name = draw(xml_texts) or f"{number}.xml"
        entries = draw(
            st.lists(
                st.builds(
                    DistortionEntry,
                    file=st.just(name),
                    line=st.integers(0, 10**6),
                    maker=xml_texts,
                    lens=xml_texts,
                    mounts=st.lists(xml_texts, max_size=2).map(tuple),
                    type=st.sampled_from(["rectilinear", "fisheye"]) | xml_texts,
                    crop_factor=any_floats,
                    aspect_ratio=any_floats,
                    model=st.sampled_from(["ptlens", "poly3", "poly5", "acm", ""]),
                    focal=any_floats,
                    real_focal=any_floats,
                    a=any_floats,
                    b=any_floats,
                    c=any_floats,
                    k1=any_floats,
                    k2=any_floats,
                    status=statuses,
                    message=xml_texts,
                ),
                max_size=3,
            )
        )
        files.append(SourceFile(name, Path("/db", f"{number}.xml"), len(entries), ""))
        per_file.append(entries)
    size = sum(map(len, per_file))
    metrics = {name: draw(st.lists(any_floats, min_size=size, max_size=size)) for name in
               METRIC_FLOAT_COLUMNS}  # fmt: skip
    metrics["tail"] = draw(st.lists(st.sampled_from([-1, 0, 1]), min_size=size, max_size=size))
    metrics["folds_in_image"] = draw(
        st.lists(st.sampled_from([0, 1]), min_size=size, max_size=size)
    )
    source = DatabaseSource((Path("/db"),), draw(xml_texts))
    entries = [entry for group in per_file for entry in group]
    columns = {name: [getattr(e, name) for e in entries] for name in DistortionEntry._fields}
    return Audit(source, files, columns, metrics)


def csv_field(value) -> str:
    if value is None or isinstance(value, bool):
        return {None: "", True: "true", False: "false"}[value]
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    return str(value)


def csv_by_the_csv_module(audit: Audit) -> str:
    """Every record through csv.writer: fields quoted where they hold a comma, a quote
    or a line break (a line terminator of CR LF makes it quote a CR too)."""
    lines = [",".join(COLUMNS)]
    for record in audit.records():
        buffer = io.StringIO()
        csv.writer(buffer, lineterminator="\r\n").writerow(map(csv_field, record.values()))
        lines.append(buffer.getvalue()[: -len("\r\n")])
    return "\n".join(lines) + "\n"


@settings(max_examples=150, deadline=None)
@given(audits())
def test_csv_is_what_the_csv_module_writes_of_every_record(audit):
    written = io.StringIO()
    writer("csv")(audit, written)
    assert written.getvalue() == csv_by_the_csv_module(audit)


def json_by_the_json_module(audit: Audit) -> str:
    """The JSON document as the standard library writes it: indented by one,
    except that each entry is one line of its own."""
    document = json_format.document(audit)
    entries = document.pop("entries")
    head = json.dumps({**document, "entries": []}, indent=1, allow_nan=False)
    if not entries:
        return head + "\n"
    lines = [
        "  " + json.dumps(entry, separators=(", ", ": "), allow_nan=False) for entry in entries
    ]
    assert head.endswith('"entries": []\n}')
    return head[: -len("]\n}")] + "\n" + ",\n".join(lines) + "\n ]\n}\n"


@settings(max_examples=150, deadline=None)
@given(audits())
def test_json_is_what_the_json_module_writes_of_the_document(audit):
    written = io.StringIO()
    writer("json")(audit, written)
    assert written.getvalue() == json_by_the_json_module(audit)
    assert json.loads(written.getvalue()) == json_format.document(audit)


def test_csv_of_the_bundled_database_is_what_the_csv_module_writes(bundled_db):
    audit = run(bundled_db)
    written = io.StringIO()
    writer("csv")(audit, written)
    assert written.getvalue() == csv_by_the_csv_module(audit)


def test_json_of_the_bundled_database_is_what_the_json_module_writes(bundled_db):
    audit = run(bundled_db)
    written = io.StringIO()
    writer("json")(audit, written)
    assert written.getvalue() == json_by_the_json_module(audit)
    assert len(written.getvalue().splitlines()) > len(audit)  # an entry a line, and the head


# --- the summary, counted without numpy, against a count with numpy ------------------------


def counted_with_numpy(audit: Audit) -> dict:
    """Tables 1 and 2 and the folding entries, counted on arrays."""
    import numpy as np

    model = np.array(audit.column("model"), dtype=object)
    rectilinear = np.array(audit.column("type"), dtype=object) == "rectilinear"
    audited = np.array(audit.column("status"), dtype=object) == "ok"
    columns = audit.metric_columns()
    r_max = np.array(columns["r_max"], dtype=float)
    tail = np.array(columns["tail"])
    folds = np.array(columns["folds_in_image"], dtype=bool)
    r_normalized = np.array(columns["r_normalized"], dtype=float)
    finite = audited & np.isfinite(r_max)
    rows = []
    for name in ("ptlens", "poly3", "poly5", None):
        mine = audited if name is None else audited & (model == name)
        rows.append(
            [
                int((mine & finite).sum()),
                int((mine & ~finite).sum()),
                int((mine & finite & (tail > 0)).sum()),
                int((mine & finite & (tail < 0)).sum()),
            ]
        )
    folding = np.flatnonzero(folds)
    folding = folding[np.argsort(r_normalized[folding], kind="stable")]
    with np.errstate(invalid="ignore"):
        paper = finite & rectilinear & (np.array(columns["r_normalized_paper"]) < 1)
    return {
        "rows": rows,
        "audited": int(audited.sum()),
        "folding": folding.tolist(),
        "folding_rectilinear": int((folds & rectilinear).sum()),
        "paper": int(paper.sum()),
    }


def counted_in_the_summary(audit: Audit) -> dict:
    summary = audit.summary
    return {
        "rows": [[r.finite, r.infinite, r.positive, r.negative] for r in summary.rows],
        "audited": summary.audited,
        "folding": summary.folding,
        "folding_rectilinear": summary.folding_rectilinear,
        "paper": summary.folding_paper_units_rectilinear,
    }


@settings(max_examples=200, deadline=None)
@given(audits(statuses=st.sampled_from(["ok", "ok", "ok", "unknown_model"])))
def test_the_summary_counts_what_numpy_counts(audit):
    assert counted_in_the_summary(audit) == counted_with_numpy(audit)


def test_the_summary_of_the_bundled_database_counts_what_numpy_counts(bundled_db):
    audit = run(bundled_db)
    assert counted_in_the_summary(audit) == counted_with_numpy(audit)


@settings(max_examples=100, deadline=None)
@given(audits(), st.integers(-12, 12))
def test_one_entry_of_an_audit_is_that_of_its_entries(audit, index):
    def exact(entry):  # NaN made equal to itself
        return tuple(repr(v) if isinstance(v, float) else v for v in entry)

    entries = [exact(e) for e in audit.entries]
    if -len(entries) <= index < len(entries):
        assert exact(audit.entry(index)) == entries[index]
    else:
        with pytest.raises(IndexError):
            audit.entry(index)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        # (after 0.0, the bytes of a C double of this tiny number hold -0.0's)
        st.sampled_from([0.0, -0.0, 1.5, math.inf, -math.inf, 1e-300, 6.3e-322, -6.3e-322])
        | any_floats,
        max_size=40,
    )
)
def test_floats_are_written_as_their_shortest_repr_or_empty(values):
    expected = ["" if math.isnan(v) else repr(v) for v in values]
    assert format_floats(values) == expected
    assert format_floats(values * 5) == expected * 5  # repeated: written once per value


@pytest.mark.parametrize(
    "values",
    [[0.0, -0.0], [-0.0, 0.0, 0.0], [0.0, 6.3e-322, 0.0], [-0.0, 6.3e-322], [0.0, -6.3e-322, -0.0]],
)
def test_each_zero_is_written_with_its_sign(values):
    assert format_floats(values * 4) == [repr(v) for v in values * 4]
