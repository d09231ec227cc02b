"""Nothing the user gave is lost on write: an output that is an input is
refused before anything is read or written, a command's files appear all or
none, Ctrl-C ends in status 130 with no partial output, and `fix --write`
keeps mode, owner and group, refuses what the user may not write, and says
what it does with links."""

from __future__ import annotations

import os
import shlex
import shutil
import signal
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from conftest import FOLDING_LENS, git_repository
from lensaudit import writing
from lensaudit.console import dispatch

FOLDING = FOLDING_LENS
BUNDLE = Path(__file__).resolve().parents[2] / "shared" / "data" / "lensfun-db-history.bundle"


def run(capsys, *words) -> tuple[int, str]:
    code = dispatch([str(w) for w in words])
    return code, capsys.readouterr().err


@pytest.fixture
def db(folding_db) -> Path:
    return folding_db


def refused(capsys, db: Path, *words) -> str:
    before = {p: p.read_bytes() for p in db.iterdir()}
    code, err = run(capsys, *words)
    assert code == 2
    assert err.count("\n") == 1 and err.startswith("lensaudit: error: ")
    assert "nothing read or written" in err
    assert {p: p.read_bytes() for p in db.iterdir()} == before  # nothing added or changed
    return err


def test_scan_refuses_to_write_over_its_input(capsys, db):
    err = refused(capsys, db, "scan", db / "a.xml", "-o", db / "a.xml")
    assert "a.xml is an input" in err


def test_scan_refuses_to_write_inside_its_input_directory(capsys, db):
    err = refused(capsys, db, "scan", db, "-f", "csv", "-o", db / "out.csv")
    assert "inside the input directory" in err


def test_another_name_of_the_input_is_the_input(capsys, db, tmp_path):
    os.link(db / "a.xml", tmp_path / "hard.xml")
    (tmp_path / "soft.xml").symlink_to(db / "a.xml")
    for alias in ("hard.xml", "soft.xml"):
        refused(capsys, db, "scan", db / "a.xml", "-o", tmp_path / alias)
    assert (tmp_path / "hard.xml").read_text() == FOLDING


@pytest.mark.parametrize(
    "words",
    [
        ("check", "{db}", "-o", "{db}/a.xml"),
        ("check", "{db}", "-o", "{db}/findings.txt"),
        ("fix", "{db}/a.xml", "-o", "{db}/a.xml"),
        ("report", "{db}", "-o", "{db}"),
        ("report", "{db}", "-o", "{db}/report"),
        ("plot", "curve", "a.xml:11", "--db", "{db}", "-o", "{db}/curve.png"),
        ("project", "{db}/a.xml", "--opencv", "1000,1000,500,500", "-o", "{db}/a.xml"),
    ],
)
def test_every_command_refuses_to_write_over_or_into_an_input(capsys, db, words):
    refused(capsys, db, *(w.format(db=db) for w in words))


@pytest.mark.parametrize(
    "name", ["entries.csv", "report.html", "fig5_r_normalized.svg", "paper_comparison.md"]
)
def test_report_refuses_an_input_file_that_it_would_replace_in_its_directory(
    capsys, db, tmp_path, name
):
    # A database file given by a name the report writes, in the report's directory:
    # --force replaces report files, never an input.
    out = tmp_path / "out"
    out.mkdir()
    given = out / name
    given.write_text(FOLDING)
    extra = ["--paper"] if name == "paper_comparison.md" else []
    code, err = run(capsys, "report", given, "-o", out, "--force", *extra)
    assert code == 2 and f"{given} is an input" in err and "nothing read or written" in err
    assert given.read_text() == FOLDING
    assert [p.name for p in out.iterdir()] == [name]


def test_check_refuses_to_write_into_its_baseline_directory(capsys, db, tmp_path):
    baseline = tmp_path / "baseline"
    shutil.copytree(db, baseline)
    before = (baseline / "a.xml").read_bytes()
    code, err = run(capsys, "check", db, "--baseline", baseline, "-o", baseline / "a.xml")
    assert code == 2 and "nothing read or written" in err
    assert (baseline / "a.xml").read_bytes() == before


def test_history_refuses_to_write_into_the_database_it_reads(capsys, tmp_path):
    repository = git_repository(tmp_path / "repo", {"data/db/a.xml": FOLDING})
    for inside in (repository / "data" / "db", repository / ".git" / "out"):
        code, err = run(capsys, "history", repository, "-o", inside, "--no-cache", "-q")
        assert code == 2 and "nothing read or written" in err
    assert sorted(p.name for p in (repository / "data" / "db").iterdir()) == ["a.xml"]


def test_writing_into_a_pipe_or_through_a_link_keeps_them(capsys, db, tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()))
    reader.start()
    assert run(capsys, "scan", db, "-f", "csv", "-o", fifo)[0] == 0
    reader.join(10)
    assert received and received[0].startswith(b"file,")
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    link = tmp_path / "link.csv"
    link.symlink_to(tmp_path / "target.csv")
    assert run(capsys, "scan", db, "-f", "csv", "-o", link)[0] == 0
    assert link.is_symlink() and (tmp_path / "target.csv").read_bytes() == received[0]


def test_a_replaced_output_keeps_its_permissions(capsys, db, tmp_path):
    out = tmp_path / "out.csv"
    out.write_text("old")
    out.chmod(0o640)
    assert run(capsys, "scan", db, "-f", "csv", "-o", out)[0] == 0
    assert stat.S_IMODE(out.stat().st_mode) == 0o640 and out.read_text().startswith("file,")


# --------------------------------------------------------------- all or none


def test_an_output_set_is_written_whole_or_not_at_all(tmp_path):
    (tmp_path / "b.txt").write_text("old b")
    with writing.OutputSet() as outputs:
        outputs.write_text(tmp_path / "a.txt", "new a")
        outputs.write_bytes(tmp_path / "b.txt", b"new b")
        assert sorted(p.name for p in tmp_path.iterdir() if not p.name.startswith(".")) == ["b.txt"]
    assert (tmp_path / "a.txt").read_text() == "new a" and (
        tmp_path / "b.txt"
    ).read_text() == "new b"
    with pytest.raises(RuntimeError), writing.OutputSet() as outputs:
        outputs.write_text(tmp_path / "a.txt", "newer a")
        raise RuntimeError("a failure after the first file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]  # no temporary left
    assert (tmp_path / "a.txt").read_text() == "new a"


def test_a_report_that_fails_half_way_writes_nothing(capsys, db, tmp_path, monkeypatch):
    from lensaudit.report import html

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(html, "render_around_figure5", broken)
    out = tmp_path / "report"
    code, err = run(capsys, "report", db, "-o", out)
    assert code == 2 and "No space left on device" in err
    assert list(out.iterdir()) == []


def test_a_history_that_fails_half_way_writes_nothing(capsys, tmp_path, monkeypatch):
    from lensaudit.cli import history as command

    written = []
    real = writing.OutputSet.write_bytes

    def fail_on_figures(self, path, data):
        written.append(path)
        raise writing.WriteError(f"cannot write {path}: disk full", "disk full")

    monkeypatch.setattr(writing.OutputSet, "write_bytes", fail_on_figures)
    repository = git_repository(tmp_path / "repo", {"data/db/a.xml": FOLDING})
    out = tmp_path / "out"
    code, err = run(capsys, "history", repository, "-o", out, "--no-cache", "-q")
    assert command is not None and written and real is not None
    assert code == 2 and "disk full" in err
    assert list(out.iterdir()) == []  # history.csv and introduced.csv were not left alone


# ------------------------------------------------------------------- Ctrl-C


def interrupted_after(seconds: float, *words) -> subprocess.CompletedProcess:
    process = subprocess.Popen(
        [sys.executable, "-m", "lensaudit", *map(str, words)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(seconds)
    process.send_signal(signal.SIGINT)
    out, err = process.communicate(timeout=120)
    return subprocess.CompletedProcess(process.args, process.returncode, out, err)


def test_ctrl_c_is_status_130_with_no_partial_output_and_a_valid_cache(tmp_path):
    if not BUNDLE.is_file():
        pytest.skip(f"no Lensfun history bundle at {BUNDLE}")
    clone = tmp_path / "lensfun"
    subprocess.run(["git", "clone", "-q", "--no-checkout", BUNDLE, clone], check=True)
    names = {"history.csv", "introduced.csv", "events.csv", "trend.png", "trend.svg"}
    cache = tmp_path / "cache"
    outcomes = set()
    for turn, delay in enumerate((0.8, 1.6, 2.4, 3.2)):
        out = tmp_path / f"out-{turn}"
        done = interrupted_after(delay, "history", clone, "-o", out, "--cache-dir", cache, "-q")
        outcomes.add(done.returncode)
        if done.returncode == 130:
            assert done.stderr.strip().splitlines()[-1] == "lensaudit: interrupted"
            assert "Traceback" not in done.stderr
        else:
            assert done.returncode == 0, done.stderr
        present = {p.name for p in out.iterdir()} if out.exists() else set()
        assert present in (set(), names)  # all of them or none
    assert 130 in outcomes
    again = tmp_path / "again"
    fresh = tmp_path / "fresh"
    for out, cache_words in ((again, ["--cache-dir", cache]), (fresh, ["--no-cache"])):
        subprocess.run(
            [sys.executable, "-m", "lensaudit", "history", clone, "-o", out, "-q", *cache_words],
            check=True,
        )
    for name in ("history.csv", "introduced.csv"):
        assert (again / name).read_bytes() == (fresh / name).read_bytes()


def test_ctrl_c_during_a_scan_leaves_no_output_file(tmp_path):
    lens = FOLDING.split("<lens>", 1)[1].rsplit("</lens>", 1)[0]
    big = tmp_path / "big.xml"
    big.write_text(
        '<lensdatabase version="2">' + f"<lens>{lens}</lens>" * 60_000 + "</lensdatabase>"
    )
    out = tmp_path / "out.csv"
    out.write_text("the last run's output")
    done = interrupted_after(1.0, "scan", big, "-f", "csv", "-o", out, "--no-cache")
    assert done.returncode == 130, done.stderr
    assert done.stderr.strip() == "lensaudit: interrupted"
    assert out.read_text() == "the last run's output"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.xml", "out.csv"]


# -------------------------------------------------------------- fix --write


def fix_write(target: Path, *prefix: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [*prefix, sys.executable, "-m", "lensaudit", "fix", "--write", "--tolerance", "5000",
         str(target)],
        capture_output=True,
        text=True,
    )  # fmt: skip


def test_fix_write_keeps_mode_owner_and_group(tmp_path):
    target = tmp_path / "a.xml"
    target.write_text(FOLDING)
    target.chmod(0o640)
    owner = (1234, 5678) if os.geteuid() == 0 else (os.getuid(), os.getgid())
    if os.geteuid() == 0:
        os.chown(target, *owner)
    done = fix_write(target)
    assert done.returncode == 0, done.stderr
    status = target.stat()
    assert target.read_text() != FOLDING
    assert stat.S_IMODE(status.st_mode) == 0o640
    assert (status.st_uid, status.st_gid) == owner


def test_fix_write_refuses_a_file_the_user_may_not_write(tmp_path):
    target = tmp_path / "a.xml"
    target.write_text(FOLDING)
    target.chmod(0o444)
    prefix: tuple[str, ...] = ()
    if os.geteuid() == 0:  # root writes anything: drop the capabilities that let it
        if shutil.which("capsh") is None:
            pytest.skip("running as root without capsh to drop CAP_DAC_OVERRIDE")
        drop = "cap_dac_override,cap_dac_read_search,cap_fowner"
        command = " ".join(
            [sys.executable, "-m", "lensaudit", "fix", "--write", "--tolerance", "5000",
             str(target)]
        )  # fmt: skip
        done = subprocess.run(
            ["capsh", f"--drop={drop}", "--", "-c", command], capture_output=True, text=True
        )
    else:
        done = fix_write(target, *prefix)
    assert done.returncode == 2
    assert "Permission denied" in done.stderr and "nothing written" in done.stderr
    assert done.stderr.count("\n") == 1
    assert target.read_text() == FOLDING


def test_fix_write_writes_through_a_symbolic_link_and_keeps_it(tmp_path):
    target = tmp_path / "real.xml"
    target.write_text(FOLDING)
    link = tmp_path / "link.xml"
    link.symlink_to(target)
    done = fix_write(link)
    assert done.returncode == 0, done.stderr
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert target.read_text() != FOLDING


def test_fix_write_refuses_a_file_with_other_hard_links(tmp_path):
    target = tmp_path / "a.xml"
    target.write_text(FOLDING)
    os.link(target, tmp_path / "other.xml")
    done = fix_write(target)
    assert done.returncode == 2 and "2 hard links" in done.stderr
    assert target.read_text() == (tmp_path / "other.xml").read_text() == FOLDING


# ------------------------------------------------ outputs that cannot be written


class WorkStarted(BaseException):
    """Raised where a command would start its work: the refusal came too late."""


@pytest.fixture
def no_work(monkeypatch):
    """Every command's work, stopped with :class:`WorkStarted` as it starts."""
    import lensaudit.check
    import lensaudit.fix
    import lensaudit.report.rmax_map
    from lensaudit import commands
    from lensaudit.cli import fix, history, plot, project, report

    def started(*args, **kwargs):
        raise WorkStarted

    for module, name in (
        (commands, "audit"), (commands, "read"), (lensaudit.check, "check"),
        (report, "audit"), (history, "audit_history"), (plot, "run"),
        (lensaudit.report.rmax_map, "rmax_map"), (fix, "run"), (lensaudit.fix, "fix_audit"),
        (project, "_opencv_camera"),
    ):  # fmt: skip
        monkeypatch.setattr(module, name, started)


@pytest.mark.parametrize(
    "words",
    [
        ("scan", "{db}", "-f", "csv", "-o", "{file}/out.csv"),
        ("scan", "{db}", "--kind", "vignetting", "-o", "{file}/out.csv"),
        ("scan", "{db}", "-o", "{missing}/out.csv"),
        ("check", "{db}", "-o", "{file}/findings.txt"),
        ("report", "{db}", "-o", "{file}/report"),
        ("report", "{db}", "-o", "{file}"),
        ("report", "{db}", "-o", "{out}", "--force"),  # {out}/entries.csv is a directory
        ("history", "{repo}", "-o", "{file}/history", "--no-cache"),
        ("history", "{repo}", "-o", "{out}", "--no-cache"),  # {out}/trend.png is a directory
        ("plot", "curve", "a.xml:10", "--db", "{db}", "-o", "{file}/curve.png"),
        ("plot", "warp", "a.xml:10", "--db", "{db}", "-o", "{file}/warp.png"),
        ("plot", "map", "-o", "{file}/map.png"),
        ("fix", "{db}", "-o", "{file}/fix.txt"),
        ("project", "--opencv", "1000,1000,500,500", "--info", "-o", "{file}/p.csv"),
    ],
)
def test_an_output_that_cannot_be_written_is_refused_before_the_work(
    capsys, db, tmp_path, no_work, words
):
    # A path under a regular file cannot be written, by root either.
    places = {
        "db": db,
        "file": tmp_path / "a-file",
        "missing": tmp_path / "no" / "such",
        "out": tmp_path / "out",
        "repo": git_repository(tmp_path / "repo", {"data/db/a.xml": FOLDING}),
    }
    places["file"].write_text("not a directory")
    for name in ("entries.csv", "trend.png"):
        (places["out"] / name).mkdir(parents=True)
    given = [w.format(**places) for w in words]
    code, err = run(capsys, *given)
    output = given[given.index("-o") + 1]
    assert code == 2, err
    assert err.count("\n") == 1 and err.startswith("lensaudit: error: cannot write")
    assert output in err or f"{output}/entries.csv" in err or f"{output}/trend.png" in err


def test_report_files_already_there_are_refused_before_the_work(capsys, db, tmp_path, no_work):
    out = tmp_path / "report"
    out.mkdir()
    (out / "table1.csv").write_text("mine\n")
    code, err = run(capsys, "report", db, "-o", out)
    assert code == 2 and "table1.csv" in err and err.count("\n") == 1
    assert (out / "table1.csv").read_text() == "mine\n"


def test_fix_write_refuses_a_file_it_cannot_patch_before_refitting(
    capsys, db, tmp_path, no_work, monkeypatch
):
    # The database is read (which files --write may patch), the refits not begun.
    from lensaudit import pipeline
    from lensaudit.cli import fix

    monkeypatch.setattr(fix, "run", pipeline.run)
    os.link(db / "a.xml", tmp_path / "other.xml")
    code, err = run(capsys, "fix", "--write", "--tolerance", "5000", db, "--no-cache")
    assert code == 2 and "2 hard links" in err and err.count("\n") == 1


#: ``lensaudit ARGS...`` as the console command runs it, its work stopped as it
#: starts (exit status 3): the history, the report's audit, fix's refits.
STOPPED_AT_THE_WORK = """\
import sys
import lensaudit.fix
from lensaudit.cli import history, report
def started(*args, **kwargs):
    sys.stderr.write("the work started\\n")
    raise SystemExit(3)
history.audit_history = report.audit = lensaudit.fix.fix_audit = started
from lensaudit.console import run
sys.argv = ["lensaudit", *sys.argv[1:]]
run()
"""


def unprivileged(*words) -> subprocess.CompletedProcess:
    """``lensaudit WORDS`` run as this user, its work stopped as it starts (see
    :data:`STOPPED_AT_THE_WORK`); as root, without the capabilities that let
    root write whatever the permissions say (skipped without capsh)."""
    command = [sys.executable, "-c", STOPPED_AT_THE_WORK, *map(str, words)]
    if os.geteuid() == 0:
        if shutil.which("capsh") is None:
            pytest.skip("running as root without capsh to drop CAP_DAC_OVERRIDE")
        drop = "cap_dac_override,cap_dac_read_search,cap_fowner"
        line = " ".join(shlex.quote(word) for word in command)
        command = ["capsh", f"--drop={drop}", "--", "-c", line]
    return subprocess.run(command, capture_output=True, text=True, timeout=600)


@pytest.mark.parametrize("command", ["history", "report", "fix"])
def test_a_directory_without_write_permission_is_refused_before_the_work(tmp_path, command):
    locked = tmp_path / "locked"
    locked.mkdir()
    words: tuple = ()
    if command == "history":
        repository = git_repository(tmp_path / "repo", {"data/db/a.xml": FOLDING})
        words = ("history", repository, "-o", locked, "--no-cache", "-q")
    elif command == "report":
        (tmp_path / "db").mkdir()
        (tmp_path / "db" / "a.xml").write_text(FOLDING)
        words = ("report", tmp_path / "db", "-o", locked / "report", "--no-cache")
    else:  # the file may be written, not its directory, where its new content goes
        (locked / "a.xml").write_text(FOLDING)
        words = ("fix", "--write", "--tolerance", "5000", locked, "--no-cache")
    locked.chmod(0o555)
    try:
        done = unprivileged(*words)
    finally:
        locked.chmod(0o755)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "Permission denied" in done.stderr
    assert str(locked) in done.stderr and done.stdout == ""
    assert sorted(p.name for p in locked.iterdir()) == (["a.xml"] if command == "fix" else [])
