"""Bad points input to `lensaudit project`: one line naming the file (and line), exit 2.

Every test runs the command on one kind of broken input and asserts exit
status 2, a single line `lensaudit: error: <file>[:<line>]: ...` and no
traceback. The camera is an OpenCV pinhole without distortion, so that
pixels of good input are u = 100 x / z + 50, v = 100 y / z + 50, known
without lensaudit.
"""

from __future__ import annotations

import csv
import errno
import io
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lensaudit.cli import main
from lensaudit.cli import project as project_module

PINHOLE = ["--opencv", "100,100,50,50"]
GOOD_CSV = b"x,y,z\n0.5,0.25,1\n-1,2,4\n0,0,2\n"
#: Pixels of GOOD_CSV through PINHOLE, by hand: 100 * x / z + 50.
GOOD_PIXELS = [(100, 75), (25, 100), (50, 50)]


def run(arguments: list[str], stdin: bytes | None = None):
    """Run `lensaudit project` in-process; any warning counts as a crash."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return CliRunner().invoke(main, ["project", *arguments, *PINHOLE], input=stdin)


def assert_one_line_error(result, prefix: str) -> str:
    """Exit 2 and exactly one line, starting `lensaudit: error: <prefix>`; returns it."""
    assert result.exit_code == 2, result.output
    assert isinstance(result.exception, SystemExit), result.exception
    assert "Traceback" not in result.output
    lines = result.output.splitlines()
    assert len(lines) == 1, result.output
    assert lines[0].startswith(f"lensaudit: error: {prefix}"), lines[0]
    return lines[0]


def pixels(output: str) -> list[tuple[float, float]]:
    return [(float(r["u"]), float(r["v"])) for r in csv.DictReader(io.StringIO(output))]


def write(tmp_path: Path, name: str, content: bytes) -> str:
    path = tmp_path / name
    path.write_bytes(content)
    return str(path)


# --- CSV text ------------------------------------------------------------------------------


def test_a_field_over_the_csv_limit_is_named_with_its_line(tmp_path):
    path = write(tmp_path, "huge.csv", b"x,y,z\n1,2,3\n" + b"7" * 200_000 + b",1,1\n")
    line = assert_one_line_error(run([path]), f"{path}:3: ")
    assert "longer than 131072 characters" in line


@pytest.mark.parametrize("newline", [b"\n", b"\r\n", b"\r"], ids=["LF", "CRLF", "CR"])
@pytest.mark.parametrize("source", ["file", "stdin"])
def test_every_kind_of_line_end_is_read(tmp_path, newline, source):
    content = GOOD_CSV.replace(b"\n", newline)
    if source == "file":
        result = run([write(tmp_path, "points.csv", content)])
    else:
        result = run(["-"], stdin=content)
    assert result.exit_code == 0, result.output
    assert pixels(result.output) == GOOD_PIXELS


def test_bare_cr_on_a_real_stdin_is_read():
    # The terminal path, not click's test runner: a bare CR once crashed csv here.
    completed = subprocess.run(
        [sys.executable, "-m", "lensaudit", "project", "-", *PINHOLE],
        input=GOOD_CSV.replace(b"\n", b"\r"),
        capture_output=True,
        timeout=60,
    )
    assert completed.returncode == 0, completed.stderr
    assert pixels(completed.stdout.decode()) == GOOD_PIXELS


def test_spreadsheet_rows_of_empty_cells_are_skipped(tmp_path):
    content = b"\xef\xbb\xbfx,y,z\r\n0.5,0.25,1\r\n,,\r\n-1,2,4\r\n\r\n0,0,2\r\n,,\r\n"
    result = run([write(tmp_path, "sheet.csv", content)])
    assert result.exit_code == 0, result.output
    assert pixels(result.output) == GOOD_PIXELS


def test_semicolon_separated_values_are_read(tmp_path):
    result = run([write(tmp_path, "points.csv", GOOD_CSV.replace(b",", b";"))])
    assert result.exit_code == 0, result.output
    assert pixels(result.output) == GOOD_PIXELS


def test_a_nul_byte_is_named_with_its_line(tmp_path):
    path = write(tmp_path, "nul.csv", b"x,y,z\n1,2,3\r\n1,\x002,3\n")
    line = assert_one_line_error(run([path]), f"{path}:3: ")
    assert "NUL byte at offset 15" in line


def test_bytes_that_are_not_utf8_are_named_with_line_and_offset(tmp_path):
    path = write(tmp_path, "latin1.csv", "x,y,z\n1,2,3\n1,2,3 \N{DEGREE SIGN}\n".encode("latin-1"))
    line = assert_one_line_error(run([path]), f"{path}:3: ")
    assert "not UTF-8 text (byte 0xb0 at offset 18)" in line


def test_bytes_that_are_not_utf8_on_stdin_are_named_with_line():
    result = run(["-"], stdin=b"1,2,3\r\xff,2,3\r")
    line = assert_one_line_error(result, "<stdin>:2: ")
    assert "byte 0xff" in line


def test_utf16_text_is_refused_with_a_hint(tmp_path):
    path = write(tmp_path, "excel.csv", GOOD_CSV.decode().encode("utf-16"))
    line = assert_one_line_error(run([path]), f"{path}: ")
    assert "UTF-16" in line


def test_a_non_numeric_value_is_named_with_its_line(tmp_path):
    path = write(tmp_path, "words.csv", b"x,y,z\n1,2,3\n\n4,five,6\n")
    line = assert_one_line_error(run([path]), f"{path}:4: ")
    assert "expected three numbers x, y, z, got ['4', 'five', '6']" in line


@pytest.mark.parametrize("value", ["nan", "inf", "-Infinity", "1e999"])
def test_a_value_that_is_not_finite_is_named_with_its_line(tmp_path, value):
    path = write(tmp_path, "nan.csv", f"x,y,z\n1,2,3\n,,\n4,{value},6\n".encode())
    line = assert_one_line_error(run([path]), f"{path}:4: ")
    assert "must be finite numbers" in line


@pytest.mark.parametrize("row", ["1,2", "1", "1;2"])
def test_a_row_with_too_few_columns_is_named_with_its_line(tmp_path, row):
    path = write(tmp_path, "short.csv", f"1,2,3\n{row}\n".encode())
    line = assert_one_line_error(run([path]), f"{path}:2: ")
    assert "expected three numbers x, y, z" in line


def test_a_row_shorter_than_the_header_is_named_with_its_line(tmp_path):
    path = write(tmp_path, "short.csv", b"id,x,y,z\n1,0,0,1\n2,0,0\n")
    line = assert_one_line_error(run([path]), f"{path}:3: ")
    assert "columns 2, 3, 4 of the header" in line


def test_a_header_without_xyz_is_named_with_its_line(tmp_path):
    path = write(tmp_path, "header.csv", b"\n\na,b,z\n1,2,3\n")
    line = assert_one_line_error(run([path]), f"{path}:3: ")
    assert "header has no column x, y" in line


def test_long_cells_are_cut_in_the_message(tmp_path):
    path = write(tmp_path, "long.csv", b"1,2,3\n1,2," + b"z" * 100_000 + b"\n")
    line = assert_one_line_error(run([path]), f"{path}:2: ")
    assert len(line) < 200 + len(path)


def test_control_characters_in_a_cell_are_escaped(tmp_path):
    path = write(tmp_path, "escape.csv", b"1,2,3\n1,2,\x1b[2J\x1b]0;x\x07\n")
    line = assert_one_line_error(run([path]), f"{path}:2: ")
    assert "\x1b" not in line and "\\x1b" in line


@pytest.mark.parametrize(
    "content",
    [b"", b"\n\n \r\n", b"\xef\xbb\xbf", b"x,y,z\n", b"x,y,z\r\n\r\n", b",,,\n,,\n"],
    ids=["empty", "blank lines", "BOM only", "header only", "header and blank", "empty cells"],
)
def test_input_without_points_is_refused(tmp_path, content):
    path = write(tmp_path, "empty.csv", content)
    line = assert_one_line_error(run([path]), f"{path}: ")
    assert "empty" in line or "no points" in line


def test_empty_stdin_is_refused():
    line = assert_one_line_error(run(["-"], stdin=b""), "<stdin>: ")
    assert "empty" in line


def test_closed_stdin_is_refused():
    completed = subprocess.run(
        ["sh", "-c", 'exec "$0" -m lensaudit project - --opencv 100,100,50,50 <&-', sys.executable],
        capture_output=True,
        timeout=60,
    )
    assert completed.returncode == 2, completed.stderr
    lines = completed.stderr.decode().splitlines()
    assert len(lines) == 1 and lines[0].startswith("lensaudit: error: <stdin>: "), lines


def run_on_a_terminal(arguments: list[str], typed: bytes | None = None):
    """`lensaudit project` in a subprocess whose standard input is a pseudo-terminal.

    ``typed`` is written to the terminal as a user would type it; without it
    nobody types, and a command that reads the terminal waits until the timeout.
    """
    pty = pytest.importorskip("pty")
    master, slave = pty.openpty()
    try:
        process = subprocess.Popen(
            [sys.executable, "-m", "lensaudit", "project", *arguments, *PINHOLE],
            stdin=slave,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        if typed is not None:
            os.write(master, typed)
        try:
            stdout, stderr = process.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            process.kill()
            process.communicate()
            pytest.fail("lensaudit project waited for a terminal")
    finally:
        os.close(master)
        os.close(slave)
    return process.returncode, stdout.decode(), stderr.decode()


def test_without_points_a_terminal_is_not_read_and_the_error_says_what_is_expected():
    code, stdout, stderr = run_on_a_terminal([])
    assert code == 2
    assert stdout == ""
    lines = stderr.splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("lensaudit: error: no POINTS: "), lines[0]
    assert "CSV" in lines[0] and ".npy" in lines[0] and "pipe" in lines[0]


def test_dash_reads_points_typed_on_a_terminal():
    # One line, then Ctrl-D (end of file in the terminal's line mode).
    code, stdout, stderr = run_on_a_terminal(["-"], typed=b"0.5,0.25,1\n\x04")
    assert code == 0, stderr
    assert pixels(stdout) == GOOD_PIXELS[:1]


def test_info_reads_no_points_on_a_terminal():
    code, stdout, stderr = run_on_a_terminal(["--info"])
    assert code == 0, stderr
    assert "r_max" in stdout


# --- .npy arrays ---------------------------------------------------------------------------


def npy_bytes(array: np.ndarray) -> bytes:
    stream = io.BytesIO()
    np.save(stream, array, allow_pickle=True)
    return stream.getvalue()


def test_npy_points_are_read_in_any_numeric_type_and_order(tmp_path):
    points = np.array([[0.5, 0.25, 1], [-1, 2, 4], [0, 0, 2]])
    # Scaling a point does not move its pixel: the int16 array projects alike.
    arrays = [points, points.astype(">f4"), np.asfortranarray(points), (points * 4).astype("i2")]
    for i, array in enumerate(arrays):
        result = run([write(tmp_path, f"p{i}.npy", npy_bytes(array))])
        assert result.exit_code == 0, result.output
        assert pixels(result.output) == GOOD_PIXELS


def test_npy_on_stdin_is_recognised_by_its_header():
    result = run(["-"], stdin=npy_bytes(np.array([[0.5, 0.25, 1.0]])))
    assert result.exit_code == 0, result.output
    assert pixels(result.output) == [(100, 75)]


def test_a_truncated_npy_is_refused(tmp_path):
    data = npy_bytes(np.zeros((100, 3)))
    path = write(tmp_path, "cut.npy", data[:-8])
    line = assert_one_line_error(run([path]), f"{path}: ")
    assert "truncated" in line and "100 x 3" in line


def test_an_npy_cut_inside_its_header_is_refused(tmp_path):
    path = write(tmp_path, "cut.npy", npy_bytes(np.zeros((100, 3)))[:40])
    line = assert_one_line_error(run([path]), f"{path}: ")
    assert "damaged .npy header" in line


def test_a_file_named_npy_that_is_not_an_array_is_refused(tmp_path):
    path = write(tmp_path, "text.npy", GOOD_CSV)
    line = assert_one_line_error(run([path]), f"{path}: ")
    assert "not a .npy array" in line


@pytest.mark.parametrize(
    "array",
    [np.zeros((4, 2)), np.zeros(3), np.zeros((2, 3, 1)), np.zeros((2, 3), dtype=bool)],
    ids=["4 x 2", "vector", "3-d", "bool"],
)
def test_an_npy_array_of_the_wrong_shape_or_type_is_refused(tmp_path, array):
    path = write(tmp_path, "shape.npy", npy_bytes(array))
    line = assert_one_line_error(run([path]), f"{path}: ")
    assert "expected a numeric N x 3 array" in line


def test_an_empty_npy_array_is_refused(tmp_path):
    path = write(tmp_path, "empty.npy", npy_bytes(np.zeros((0, 3))))
    line = assert_one_line_error(run([path]), f"{path}: ")
    assert "no points" in line


def test_an_npy_row_that_is_not_finite_is_named(tmp_path):
    points = np.ones((5, 3))
    points[3, 1] = np.nan
    path = write(tmp_path, "nan.npy", npy_bytes(points))
    line = assert_one_line_error(run([path]), f"{path}: ")
    assert "row 3 (from 0) is not finite" in line


class _OpensAFile:
    """Unpickling this creates a file: proof that a pickle was loaded."""

    def __init__(self, path: Path):
        self.path = path

    def __reduce__(self):
        return (open, (str(self.path), "w"))


def test_a_pickle_inside_an_npy_is_never_loaded(tmp_path):
    marker = tmp_path / "unpickled"
    data = npy_bytes(np.array([_OpensAFile(marker)] * 3, dtype=object))
    path = write(tmp_path, "pickle.npy", data)
    line = assert_one_line_error(run([path]), f"{path}: ")
    assert "Python objects" in line
    assert not marker.exists()


def test_a_zip_archive_is_refused_with_a_hint(tmp_path):
    stream = io.BytesIO()
    np.savez(stream, points=np.zeros((2, 3)))
    path = write(tmp_path, "points.npz", stream.getvalue())
    line = assert_one_line_error(run([path]), f"{path}: ")
    assert "zip archive" in line


# --- what POINTS names ---------------------------------------------------------------------


def test_a_missing_file_is_refused(tmp_path):
    path = str(tmp_path / "nowhere.csv")
    line = assert_one_line_error(run([path]), f"{path}: ")
    assert "No such file" in line


def test_a_directory_is_refused(tmp_path):
    line = assert_one_line_error(run([str(tmp_path)]), f"{tmp_path}: ")
    assert "a directory, not a regular file" in line


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
def test_a_fifo_is_refused_without_waiting_for_a_writer(tmp_path):
    fifo = tmp_path / "points.csv"
    os.mkfifo(fifo)
    completed = subprocess.run(
        [sys.executable, "-m", "lensaudit", "project", str(fifo), *PINHOLE],
        capture_output=True,
        timeout=60,
    )
    assert completed.returncode == 2
    lines = completed.stderr.decode().splitlines()
    assert lines == [
        f"lensaudit: error: {fifo}: a FIFO, not a regular file; "
        "give a CSV or .npy file, or - for standard input"
    ]


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero")
def test_a_device_is_refused():
    line = assert_one_line_error(run(["/dev/zero"]), "/dev/zero: ")
    assert "a character device" in line


@pytest.mark.skipif(
    not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root reads files without permission"
)
def test_an_unreadable_file_is_refused(tmp_path):
    path = write(tmp_path, "secret.csv", GOOD_CSV)
    os.chmod(path, 0)
    line = assert_one_line_error(run([path]), f"{path}: ")
    assert "Permission denied" in line


def test_a_permission_error_is_one_line(tmp_path, monkeypatch):
    # The same as the test above, also where the tests run as root.
    path = write(tmp_path, "secret.csv", GOOD_CSV)
    real_open = os.open

    def refuse(file, *args, **kwargs):
        if os.fspath(file) == path:
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), path)
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(project_module.os, "open", refuse)
    line = assert_one_line_error(run([path]), f"{path}: ")
    assert line.endswith(os.strerror(errno.EACCES))


def test_a_too_long_file_name_is_refused_and_shortened(tmp_path):
    path = str(tmp_path / ("p" * 5000 + ".csv"))
    result = run([path])
    line = assert_one_line_error(result, str(tmp_path)[:20])
    assert os.strerror(errno.ENAMETOOLONG) in line
    assert len(line) < 300


def test_control_characters_in_a_file_name_are_escaped(tmp_path):
    path = write(tmp_path, "a\nb\x1b.csv", b"1,2\n")
    result = run([path])
    line = assert_one_line_error(result, f"{tmp_path}/a\\nb\\x1b.csv:1: ")
    assert "expected three numbers" in line


# --- anything at all -----------------------------------------------------------------------

FUZZ = settings(
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


def assert_clean_exit(result) -> None:
    """Exit 0 with CSV, or exit 2 with one error line; never an exception or a warning."""
    assert result.exit_code in (0, 2), (result.exit_code, result.output, result.exception)
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    assert "Traceback" not in result.output
    if result.exit_code == 2:
        lines = result.output.splitlines()
        assert len(lines) == 1 and lines[0].startswith("lensaudit: error: "), result.output
    else:
        assert result.output.startswith("u,v,valid\n")


@FUZZ
@given(data=st.binary(max_size=300))
def test_random_bytes_never_crash(tmp_path, data):
    for name in ("points.csv", "points.npy"):
        assert_clean_exit(run([write(tmp_path, name, data)]))
    assert_clean_exit(run(["-"], stdin=data))


def mutated(base: bytes) -> st.SearchStrategy[bytes]:
    """base with bytes deleted, replaced or inserted at random places."""
    edit = st.tuples(
        st.sampled_from(["delete", "replace", "insert"]),
        st.integers(0, len(base)),
        st.binary(min_size=1, max_size=4)
        | st.sampled_from([b"\r", b"\n", b"\r\n", b",", b";", b'"', b"\x00", b"nan", b"\xff"]),
    )

    def apply(edits: list[tuple[str, int, bytes]]) -> bytes:
        data = bytearray(base)
        for kind, at, chunk in edits:
            at = min(at, len(data))
            if kind == "delete":
                del data[at : at + len(chunk)]
            elif kind == "replace":
                data[at : at + len(chunk)] = chunk
            else:
                data[at:at] = chunk
        return bytes(data)

    return st.lists(edit, min_size=1, max_size=6).map(apply)


@FUZZ
@given(data=mutated(GOOD_CSV))
def test_mutated_csv_never_crashes(tmp_path, data):
    assert_clean_exit(run([write(tmp_path, "points.csv", data)]))
    assert_clean_exit(run(["-"], stdin=data))


@FUZZ
@given(data=mutated(npy_bytes(np.array([[0.5, 0.25, 1.0], [-1.0, 2.0, 4.0]]))))
def test_mutated_npy_never_crashes(tmp_path, data):
    assert_clean_exit(run([write(tmp_path, "points.npy", data)]))
