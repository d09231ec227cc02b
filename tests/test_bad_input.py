"""Bad input a database editor produces by mistake: every case ends in a status
row or one line naming the path and the problem (exit 2), never a traceback,
a hang, a warning, or an answer read wrongly.

References are independent of the loader: the standard library's XML parser
for text content, hand-counted entries for the small files written here.
"""

from __future__ import annotations

import csv
import io
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import lens_xml
from lensaudit.cli import main
from lensaudit.read import paths
from lensaudit.read.paths import bundled_database_path, resolve

TWO_LENSES = """\
<lensdatabase version="2">
    <lens>
        <maker>Test</maker>
        <model>Broken ratio</model>
        <mount>M</mount>
        <aspect-ratio>{aspect}</aspect-ratio>
        <calibration>
            <distortion model="ptlens" focal="10" a="0.01" b="-0.02" c="0.01"/>
        </calibration>
    </lens>
    <lens>
        <maker>Test</maker>
        <model>Fine</model>
        <mount>M</mount>
        <cropfactor>{crop}</cropfactor>
        <calibration>
            <distortion model="poly3" focal="10" k1="-0.1" {real_focal}/>
        </calibration>
    </lens>
</lensdatabase>
"""


def rows(result) -> list[dict[str, str]]:
    # The bytes as written: click's ``output`` turns "\r\n" inside a quoted name into "\n".
    text = result.stdout_bytes.decode("utf-8")
    return list(csv.DictReader(io.StringIO(text, newline="")))


def scan_csv(*paths) -> list[dict[str, str]]:
    result = CliRunner().invoke(main, ["scan", "--format", "csv", *map(str, paths)])
    assert result.exit_code == 0, result.output
    return rows(result)


def run_cli(*arguments: str, timeout: float = 60) -> subprocess.CompletedProcess:
    """The installed command in a fresh process, as a user runs it (real stdout)."""
    return subprocess.run(
        [sys.executable, "-m", "lensaudit", *arguments],
        capture_output=True,
        timeout=timeout,
        env={**os.environ, "PYTHONIOENCODING": "utf-8"},
    )


def assert_one_line_error(process: subprocess.CompletedProcess, *fragments: str) -> None:
    """Exit 2, one line on stderr naming what is wrong, nothing else."""
    stderr = process.stderr.decode("utf-8", "replace")
    assert process.returncode == 2, stderr
    assert "Traceback" not in stderr and "Warning" not in stderr
    assert len(stderr.strip().splitlines()) == 1, stderr
    for fragment in fragments:
        assert fragment in stderr


# --- values --------------------------------------------------------------------


def test_zero_denominator_aspect_ratio_is_a_bad_value_and_the_other_lens_is_audited(write_xml):
    path = write_xml(TWO_LENSES.format(aspect="3:0", crop="1.5", real_focal=""))
    broken, fine = scan_csv(path)
    assert broken["status"] == "bad_value" and "3:0" in broken["message"]
    assert fine["status"] == "ok" and fine["r_max"] != ""


def test_empty_real_focal_is_a_bad_value_not_one_millimetre(write_xml):
    path = write_xml(TWO_LENSES.format(aspect="4:3", crop="1.5", real_focal='real-focal=""'))
    _, entry = scan_csv(path)
    assert entry["status"] == "bad_value"
    assert "real-focal" in entry["message"]
    assert entry["real_focal"] == ""


def test_text_split_by_a_comment_is_read_as_liblensfun_reads_it(write_xml):
    from liblensfun_master import lenses

    text = TWO_LENSES.format(aspect="4:3", crop="1<!-- note -->.5", real_focal="")
    text = text.replace("<maker>Test</maker>", "<maker>Te<!-- a note -->st</maker>", 1)
    theirs = {lens["model"]: lens for lens in lenses(text.encode())}
    broken, fine = scan_csv(write_xml(text))
    assert float(fine["crop_factor"]) == pytest.approx(theirs["Fine"]["crop_factor"], rel=1e-6)
    assert theirs["Fine"]["crop_factor"] == pytest.approx(0.5)  # the text after the comment
    assert broken["maker"] == theirs["Broken ratio"]["maker"] == "st"


@pytest.mark.parametrize("reference", ["&#xD800;", "&#55296;", "&#x000dfff;", "&#57343;"])
@pytest.mark.parametrize("where", ["maker", "attribute"])
def test_a_reference_to_a_surrogate_leaves_a_broken_file_whose_entries_are_kept(
    write_xml, reference, where
):
    # No XML text may hold a surrogate: the file is not well-formed, and what
    # recovery mode reads of it must still be text (an entry row each).
    write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.01"/>'), "good.xml")
    text = TWO_LENSES.format(aspect="4:3", crop="1.5", real_focal="")
    if where == "maker":
        text = text.replace("<maker>Test</maker>", f"<maker>T{reference}</maker>", 1)
    else:
        text = text.replace('focal="10" a=', f'focal="10" note="{reference}" a=', 1)
    path = write_xml(text, "broken.xml")
    found = scan_csv(path.parent)
    by_file: dict[str, list[str]] = {}
    for row in found:
        by_file.setdefault(row["file"], []).append(row["status"])
    assert by_file == {"broken.xml": ["xml_error"] * 3, "good.xml": ["ok"]}
    broken = [row for row in found if row["file"] == "broken.xml"]
    line = 3 if where == "maker" else 8
    assert f"at line {line}, column" in broken[0]["message"]
    assert [row["lens"] for row in broken[1:]] == ["Broken ratio", "Fine"]
    for command in (["check"], ["report", "-o", str(path.parent.parent / "out")]):
        process = run_cli(*command, str(path.parent), "--no-cache")
        stderr = process.stderr.decode("utf-8", "replace")
        assert process.returncode in (0, 1) and "Traceback" not in stderr, stderr


# --- what a file is ------------------------------------------------------------


def test_namespaced_database_is_read_like_the_same_database_without_namespace(tmp_path):
    plain = TWO_LENSES.format(aspect="4:3", crop="1.5", real_focal="")
    spaced = plain.replace("<lensdatabase ", '<lensdatabase xmlns="http://example.org/lf" ')
    (tmp_path / "plain.xml").write_text(plain)
    (tmp_path / "spaced.xml").write_text(spaced)
    expected = scan_csv(tmp_path / "plain.xml")
    found = scan_csv(tmp_path / "spaced.xml")
    assert len(found) == 2
    for row in (*expected, *found):
        row.pop("file")
    assert found == expected


def test_a_file_that_is_not_a_lensfun_database_alone_exits_2(tmp_path):
    page = tmp_path / "page.xml"
    page.write_text('<html xmlns="http://www.w3.org/1999/xhtml"><body>lens</body></html>')
    assert_one_line_error(run_cli("scan", str(page)), "page.xml", "not a Lensfun database")


def test_a_file_that_is_not_a_lensfun_database_is_a_status_row_beside_good_files(write_xml):
    write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.01"/>'), "good.xml")
    path = write_xml(
        "<html><body><distortion model='poly3' focal='10' k1='0.1'/></body></html>", "page.xml"
    )
    found = scan_csv(path.parent)
    by_file = {}
    for row in found:
        by_file.setdefault(row["file"], []).append(row)
    assert [r["status"] for r in by_file["good.xml"]] == ["ok"]
    # The file itself, and the <distortion> inside it: nothing is lost, nothing audited.
    assert [r["status"] for r in by_file["page.xml"]] == ["not_database"] * 2
    assert "<html>" in by_file["page.xml"][0]["message"]


def test_check_fails_on_a_file_that_is_not_a_lensfun_database(write_xml):
    write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.01"/>'), "good.xml")
    path = write_xml("<html><body>no lenses</body></html>", "page.xml")
    result = CliRunner().invoke(main, ["check", str(path.parent)])
    assert result.exit_code == 1, result.output
    assert "page.xml" in result.output and "not a Lensfun database" in result.output


# --- paths ---------------------------------------------------------------------


def test_the_same_database_named_three_times_is_audited_once(bundled_db):
    once = scan_csv(bundled_db)
    thrice = scan_csv(bundled_db, bundled_db, bundled_db / "contax.xml")
    assert len(thrice) == len(once)


def test_fifo_given_as_path_is_refused_without_hanging(tmp_path):
    fifo = tmp_path / "db.xml"
    os.mkfifo(fifo)
    assert_one_line_error(run_cli("scan", str(fifo), timeout=30), "db.xml", "not a regular file")


def test_device_given_as_path_is_refused_without_hanging():
    assert_one_line_error(run_cli("scan", "/dev/zero", timeout=30), "/dev/zero")


def test_fifo_inside_a_database_directory_is_a_status_row(write_xml):
    path = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.01"/>'))
    os.mkfifo(path.parent / "pipe.xml")
    statuses = {row["file"]: row["status"] for row in scan_csv(path.parent)}
    assert statuses == {"test.xml": "ok", "pipe.xml": "unreadable"}


def test_too_long_a_path_name_is_one_line_and_exit_2(tmp_path):
    name = str(tmp_path / ("x" * 300 + ".xml"))
    assert_one_line_error(run_cli("scan", name), "File name too long")


def test_unreadable_file_is_a_status_row_with_the_reason(write_xml, monkeypatch):
    good = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.01"/>'), "good.xml")
    locked = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.01"/>'), "locked.xml")
    real = paths.read_file

    def read_file(path):
        if Path(path).name == locked.name:
            raise PermissionError(13, "Permission denied")
        return real(path)

    monkeypatch.setattr(paths, "read_file", read_file)
    result = CliRunner().invoke(main, ["scan", "--no-cache", "--format", "csv", str(good.parent)])
    statuses = {row["file"]: (row["status"], row["message"]) for row in rows(result)}
    assert statuses["good.xml"][0] == "ok"
    assert statuses["locked.xml"] == ("unreadable", "cannot read file: Permission denied")


def test_directory_that_cannot_be_listed_is_one_line_and_exit_2(tmp_path, monkeypatch):
    real = os.scandir

    def scandir(path):
        if Path(path) == tmp_path:
            raise PermissionError(13, "Permission denied")
        return real(path)

    monkeypatch.setattr(os, "scandir", scandir)
    result = CliRunner().invoke(main, ["scan", str(tmp_path)])
    assert result.exit_code == 2
    assert "cannot list directory: Permission denied" in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit)


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads files whatever their permissions")
def test_file_without_read_permission_is_a_status_row(write_xml):
    good = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.01"/>'), "good.xml")
    locked = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.01"/>'), "locked.xml")
    locked.chmod(0)
    statuses = {row["file"]: row["status"] for row in scan_csv(good.parent)}
    assert statuses == {"good.xml": "ok", "locked.xml": "unreadable"}


NON_UTF8 = os.fsdecode(b"caf\xff.xml")


@pytest.mark.parametrize("command", [["scan", "--format", "csv"], ["scan"], ["check"]])
def test_file_name_that_is_not_utf8_is_printed_with_a_backslash_escape(tmp_path, command):
    (tmp_path / NON_UTF8).write_text(lens_xml('<distortion model="poly3" focal="10" k1="-0.3"/>'))
    process = run_cli(*command, str(tmp_path / NON_UTF8))
    stdout = process.stdout.decode("utf-8")
    assert process.returncode in (0, 1), process.stderr
    assert b"Traceback" not in process.stderr
    assert "caf\\xff.xml" in stdout


def test_report_of_a_directory_with_every_kind_of_bad_file_is_written(tmp_path):
    database = tmp_path / "db"
    database.mkdir()
    (database / NON_UTF8).write_text(lens_xml('<distortion model="poly3" focal="10" k1="-0.3"/>'))
    (database / "ratio.xml").write_text(TWO_LENSES.format(aspect="3:0", crop="1", real_focal=""))
    (database / "page.xml").write_text("<html><body/></html>")
    os.mkfifo(database / "pipe.xml")
    process = run_cli("report", str(database), "-o", str(tmp_path / "out"), timeout=120)
    assert process.returncode == 0, process.stderr.decode()
    assert b"Traceback" not in process.stderr and b"Warning" not in process.stderr
    entries = (tmp_path / "out" / "entries.csv").read_text(encoding="utf-8")
    for expected in ("caf\\xff.xml", "ratio.xml", "page.xml", "pipe.xml"):
        assert expected in entries


# --- the database a user means ---------------------------------------------------


def lensfun_checkout(root: Path) -> Path:
    """A directory laid out like a clone of the Lensfun repository."""
    database = root / "data" / "db"
    database.mkdir(parents=True)
    for name in ("contax.xml", "6x6.xml"):
        (database / name).write_bytes((bundled_database_path() / name).read_bytes())
    (database / "lensfun-database.dtd").write_text("<!ELEMENT lensdatabase ANY>\n")
    (database / "timestamp.txt").write_text("1700000000\n")
    (root / "docs").mkdir()
    (root / "docs" / "manual.xml").write_text("<manual/>")
    return database


def test_a_lensfun_checkout_given_as_path_is_its_data_db(tmp_path):
    database = lensfun_checkout(tmp_path / "lensfun")
    expected = scan_csv(database)
    assert {row["file"] for row in expected} == {"contax.xml", "6x6.xml"}
    assert scan_csv(tmp_path / "lensfun") == expected


def test_without_path_inside_a_lensfun_checkout_its_database_is_read_and_named(
    tmp_path, monkeypatch
):
    database = lensfun_checkout(tmp_path / "lensfun")
    monkeypatch.chdir(tmp_path / "lensfun" / "docs")
    assert resolve(None).paths == (database,)
    result = CliRunner().invoke(main, ["scan"])
    assert result.exit_code == 0, result.output
    assert str(database) in result.output.splitlines()[0]
    assert "bundled" not in result.output


def test_the_git_commit_of_a_checkout_is_named(tmp_path):
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t", "-C", str(tmp_path / "lensfun")]
    lensfun_checkout(tmp_path / "lensfun")
    try:
        subprocess.run([*git, "init", "-q"], check=True)
        subprocess.run([*git, "add", "."], check=True)
        subprocess.run([*git, "commit", "-qm", "db"], check=True)
    except (OSError, subprocess.CalledProcessError):
        pytest.skip("git is not available")
    commit = subprocess.run(
        [*git, "rev-parse", "--short=10", "HEAD"], capture_output=True, text=True, check=True
    ).stdout.strip()
    result = CliRunner().invoke(main, ["scan", str(tmp_path / "lensfun")])
    assert f"git commit {commit}" in result.output.splitlines()[0]


# --- fuzzed file names -------------------------------------------------------------

name_bytes = st.binary(min_size=1, max_size=40).filter(
    lambda b: b"/" not in b and b"\0" not in b and b not in (b".", b"..")
)


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(stem=name_bytes)
def test_any_file_name_is_scanned_and_reported_with_escapes(tmp_path_factory, stem):
    directory = tmp_path_factory.mktemp("names")
    name = os.fsdecode(stem + b".xml")
    try:
        (directory / name).write_bytes((bundled_database_path() / "contax.xml").read_bytes())
    except OSError:  # a name the file system refuses (too long once encoded, say)
        return
    found = scan_csv(directory)
    shown = (stem + b".xml").decode(sys.getfilesystemencoding(), "backslashreplace")
    assert found and {row["file"] for row in found} == {shown}
    assert all(row["status"] == "ok" for row in found)


@pytest.mark.parametrize("command", ["scan", "check", "report", "history"])
def test_every_command_names_a_too_long_path_in_one_line(tmp_path, command):
    name = str(tmp_path / ("y" * 300))
    extra = ["-o", str(tmp_path / "out")] if command in ("report", "history") else []
    assert_one_line_error(run_cli(command, name, *extra), "File name too long")


@pytest.mark.parametrize(
    "arguments, fragment",
    [
        (["scan", "-o", "{tmp}"], "is a directory"),
        (["scan", "--format", "xml"], "'xml' is not one of"),
        (["scna"], "No such command 'scna'"),
        (["--bogus"], "No such option '--bogus'"),
    ],
)
def test_bad_usage_is_one_line_and_exit_2(tmp_path, arguments, fragment):
    arguments = [a.format(tmp=tmp_path) for a in arguments]
    assert_one_line_error(run_cli(*arguments), fragment, "--help")
