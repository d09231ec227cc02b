"""Every command ends cleanly, whatever the terminal and the signals.

A terminal whose encoding cannot show a name, standard output or error
closed, Ctrl-C at any moment, control characters in a name: each command
prints what it can, escaped, and ends with one line and its status, never a
traceback. The commands run as a shell runs them, in a process of their own.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

import pytest

from conftest import lens_xml

FOLDING = '<distortion model="poly3" focal="10" k1="-0.3"/>'
MAKER, LENS = "Зенит", "Гелиос–44 α"
#: A carriage return, a C1 control (CSI) and a right-to-left override in a lens name.
HOSTILE = "Гелиос–44 α&#13;\u009b31m\u202eX"
#: None of these may reach a terminal raw.
RAW_CONTROLS = ("\r", "\u009b", "\u202e")


def command(*words: str, **environment: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "lensaudit", *words],
        capture_output=True,
        env={**os.environ, **environment},
        timeout=120,
    )


def in_shell(redirection: str, *words: str) -> subprocess.CompletedProcess:
    """`python -m lensaudit WORDS... REDIRECTION` as a shell runs it (``>&-``: closed)."""
    return subprocess.run(
        ["sh", "-c", f'exec "$@" {redirection}', "sh", sys.executable, "-m", "lensaudit", *words],
        capture_output=True,
        timeout=120,
    )


@pytest.fixture
def named(write_xml) -> Path:
    """A database whose folding lens has a Cyrillic maker and a Cyrillic, Greek, en-dash name."""
    xml = lens_xml(FOLDING).replace("<maker>Test</maker>", f"<maker>{MAKER}</maker>")
    return write_xml(xml.replace("<model>Test 10mm</model>", f"<model>{LENS}</model>")).parent


@pytest.fixture
def hostile(write_xml) -> Path:
    """A database whose folding lens's name holds control characters, and a second
    lens of that name at 12 mm (so that a query for it is ambiguous)."""
    xml = lens_xml(FOLDING, FOLDING.replace('"10"', '"12"'))
    return write_xml(xml.replace("<model>Test 10mm</model>", f"<model>{HOSTILE}</model>")).parent


# Command line, exit status, what the maker or the lens becomes on an ASCII
# or Latin-1 terminal.
UNENCODABLE = [
    (["scan"], 0, "\\u0417\\u0435\\u043d\\u0438\\u0442"),
    (["scan", "-f", "csv"], 0, "\\u0417\\u0435\\u043d\\u0438\\u0442"),
    (["check"], 1, "\\u0417\\u0435\\u043d\\u0438\\u0442 \\u0413"),
    (["check", "--format", "github"], 1, "\\u0417\\u0435\\u043d\\u0438\\u0442 \\u0413"),
    (["check", "--format", "junit"], 1, "&#1047;&#1077;&#1085;&#1080;&#1090; &#1043;"),
    (["fix"], 0, "\\u0413\\u0435\\u043b\\u0438\\u043e\\u0441\\u201344 \\u03b1"),
]


@pytest.mark.parametrize("encoding", ["iso-8859-1", "ascii"])
@pytest.mark.parametrize(("words", "status", "shown"), UNENCODABLE)
def test_a_terminal_that_cannot_show_a_name_gets_it_escaped(named, encoding, words, status, shown):
    done = command(*words, str(named), PYTHONIOENCODING=encoding)
    assert done.returncode == status, done.stderr.decode()
    assert done.stderr == b""
    output = done.stdout.decode(encoding)
    assert shown in output
    if "junit" in words:  # still the document it says it is: UTF-8 (of which ASCII is part)
        assert output.startswith('<?xml version="1.0" encoding="UTF-8"?>') and output.isascii()


@pytest.mark.parametrize("encoding", ["iso-8859-1", "ascii"])
def test_an_error_quoting_a_name_is_escaped_on_such_a_terminal(named, encoding):
    missing = named / f"{LENS}.xml"
    done = command("scan", str(missing), PYTHONIOENCODING=encoding)
    assert done.returncode == 2
    line = done.stderr.decode(encoding)
    assert line.startswith("lensaudit: error: ") and "\\u0413" in line
    assert line.count("\n") == 1 and "Traceback" not in line


@pytest.mark.parametrize("output_format", ["csv", "table"])
def test_a_file_written_with_output_stays_utf8_whatever_the_terminal(
    named, tmp_path, output_format
):
    target = tmp_path / f"entries.{output_format}"
    done = command(
        "scan", "-f", output_format, "-o", str(target), str(named), PYTHONIOENCODING="ascii"
    )
    assert done.returncode == 0, done.stderr.decode()
    assert MAKER in target.read_text(encoding="utf-8")


# Command lines that write to standard output, and the status each ends with
# when it can.
STDOUT_COMMANDS = [
    ["scan"],
    ["scan", "-f", "csv"],
    ["scan", "--kind", "vignetting"],
    ["check"],
    ["check", "--format", "json"],
    ["fix"],
    ["project", "--lens", "Гел", "--focal", "10", "--size", "6000x4000", "--info", "--db"],
]


@pytest.mark.parametrize("words", STDOUT_COMMANDS, ids=" ".join)
def test_closed_standard_output_is_one_line_and_status_2(named, words):
    done = in_shell(">&-", *words, str(named))
    assert done.returncode == 2
    assert done.stderr == b"lensaudit: error: standard output is closed\n"


@pytest.mark.parametrize("words", [["--help"], ["-h"], ["--version"], ["check", "--help"]])
def test_closed_standard_output_for_help_and_version_is_one_line_and_status_2(words):
    done = in_shell(">&-", *words)
    assert done.returncode == 2
    assert done.stderr == b"lensaudit: error: standard output is closed\n"


def test_closed_standard_output_is_no_error_when_the_output_is_a_file(named, tmp_path):
    target = tmp_path / "entries.csv"
    done = in_shell(">&-", "scan", "-f", "csv", "-o", str(target), str(named))
    assert done.returncode == 0, done.stderr.decode()
    assert MAKER in target.read_text(encoding="utf-8")


@pytest.mark.parametrize(
    ("words", "status"),
    [(["scan", "-f", "csv"], 0), (["check"], 1), (["fix"], 0), (["scan", "missing.xml"], 2)],
)
def test_closed_standard_error_is_no_traceback(named, words, status):
    done = in_shell("2>&-", *words, str(named))
    assert done.returncode == status
    assert b"Traceback" not in done.stdout


def test_closed_standard_output_and_error_end_with_status_2(named):
    done = in_shell(">&- 2>&-", "check", str(named))
    assert (done.returncode, done.stdout, done.stderr) == (2, b"", b"")


def assert_no_raw_controls(text: str) -> None:
    assert not set(text) & set(RAW_CONTROLS), text


def test_fix_escapes_control_characters_in_its_table(hostile):
    done = command("fix", str(hostile))
    assert done.returncode == 0, done.stderr.decode()
    output = done.stdout.decode()
    assert_no_raw_controls(output)
    assert "\\x0d\\x9b31m\\u202eX" in output


def test_plot_escapes_control_characters_in_its_list_of_candidates(hostile, tmp_path):
    done = command("plot", "curve", "--lens", "Гелиос", "--db", str(hostile), "-o", "x.png")
    assert done.returncode == 2
    listed = done.stderr.decode()
    assert_no_raw_controls(listed)
    assert listed.count("\\x9b31m\\u202eX") == 2, listed


def test_project_escapes_control_characters_in_its_messages(hostile, tmp_path):
    points = tmp_path / "points.csv"
    points.write_text("x,y,z\n0.1,0.1,1\n")
    words = ["--lens", "Гелиос", "--focal", "10", "--db", str(hostile), "--size", "6000x4000"]
    done = command("project", str(points), *words)
    assert done.returncode == 0, done.stderr.decode()
    assert_no_raw_controls(done.stderr.decode())
    assert "\\x9b31m\\u202eX at 10 mm" in done.stderr.decode()


def test_report_and_errors_escape_control_characters_in_names(hostile, tmp_path):
    strange = tmp_path / "db\u009b2J\u202e"
    hostile.rename(strange)
    done = command("report", "-o", str(tmp_path / "out"), str(strange))
    assert done.returncode == 0, done.stderr.decode()
    assert_no_raw_controls(done.stdout.decode() + done.stderr.decode())
    assert "db\\x9b2J\\u202e" in done.stdout.decode()
    done = command("scan", str(strange / "missing\r.xml"))
    assert done.returncode == 2
    assert_no_raw_controls(done.stderr.decode())
    assert done.stderr.decode().count("\n") == 1


# Ctrl-C ------------------------------------------------------------------

#: The console script as installed beside this interpreter.
SCRIPT = Path(sysconfig.get_path("scripts")) / "lensaudit"
#: Delays after the start at which Ctrl-C comes: over the start-up imports, the
#: reading (lxml's own import), the audit and the output of a cold scan.
DELAYS = [step * 0.025 for step in range(25)]


def interrupted_after(
    delay: float, start: list[str], database: Path, cache: Path
) -> subprocess.CompletedProcess:
    environment = {**os.environ, "LENSAUDIT_CACHE_DIR": str(cache)}
    with subprocess.Popen(
        [*start, "scan", "-f", "csv", str(database)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=environment,
    ) as process:
        time.sleep(delay)
        process.send_signal(signal.SIGINT)
        stdout, stderr = process.communicate(timeout=120)
    return subprocess.CompletedProcess(process.args, process.returncode, stdout, stderr)


def before_lensaudit(done: subprocess.CompletedProcess) -> bool:
    """Whether Ctrl-C came before lensaudit's first line ran: while the
    interpreter started (ended by the signal, silently) or ran site's .pth
    files, which lensaudit cannot see (a traceback without a frame of it)."""
    if done.returncode == -signal.SIGINT and not done.stderr:
        return True
    error = done.stderr.decode()
    return error.rstrip().endswith("KeyboardInterrupt") and "lensaudit" not in error


@pytest.mark.parametrize("how", ["python -m lensaudit", "lensaudit script"])
def test_ctrl_c_at_any_moment_ends_with_interrupted_and_status_130(bundled_db, tmp_path, how):
    start = [sys.executable, "-m", "lensaudit"] if how.startswith("python") else [str(SCRIPT)]
    whole = command("scan", "-f", "csv", "--no-cache", str(bundled_db)).stdout
    interrupted = 0
    for index, delay in enumerate(DELAYS):
        done = interrupted_after(delay, start, bundled_db, tmp_path / f"cache{index}")
        if done.returncode == 0:  # the scan was over: all of it was written
            assert done.stdout == whole and not done.stderr, delay
        elif not before_lensaudit(done):
            assert done.returncode == 130, (delay, done.stderr.decode())
            assert done.stderr == b"lensaudit: interrupted\n", (delay, done.stderr.decode())
            interrupted += 1
    assert interrupted >= len(DELAYS) // 2  # the sweep did reach lensaudit's own work


# Ctrl-C while lxml initialises: its module's code registers its classes with
# abc, and an exception raised there (by a signal handler) is lost.
LOST_IN_LXML = """
import os, signal, sys
from lensaudit import console

def interrupt_in_lxml(frame, event, argument):
    if event == "call" and frame.f_code.co_name == "register" and "lxml.etree" in sys.modules:
        sys.setprofile(None)
        os.kill(os.getpid(), signal.SIGINT)

sys.argv[0] = "lensaudit"
sys.setprofile(interrupt_in_lxml)
console.run()
"""


def test_ctrl_c_lost_in_code_not_lensaudits_still_ends_the_command(named):
    done = subprocess.run(
        [sys.executable, "-c", LOST_IN_LXML, "scan", "-f", "csv", "--no-cache", str(named)],
        capture_output=True,
        timeout=120,
    )
    assert (done.returncode, done.stdout) == (130, b"")
    assert done.stderr == b"lensaudit: interrupted\n"
