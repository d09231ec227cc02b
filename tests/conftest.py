"""Shared fixtures: the bundled Lensfun database and small hand-made XML files."""

from __future__ import annotations

import os
import textwrap
from collections.abc import Callable
from pathlib import Path

import pytest

from lensaudit.read.paths import bundled_database_path

#: Git run by the tests: a fixed identity, and no system or user configuration.
GIT_ENVIRONMENT = {
    "GIT_AUTHOR_NAME": "Test",
    "GIT_AUTHOR_EMAIL": "test@example.org",
    "GIT_COMMITTER_NAME": "Test",
    "GIT_COMMITTER_EMAIL": "test@example.org",
    "GIT_CONFIG_NOSYSTEM": "1",
    "GIT_CONFIG_GLOBAL": os.devnull,
}


@pytest.fixture(autouse=True)
def isolated_cache_directories(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every test caches in its own temporary directories, never in the user's ~/.cache."""
    monkeypatch.setenv("LENSAUDIT_CACHE_DIR", str(tmp_path / "lensaudit-cache"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg-cache"))


@pytest.fixture(scope="session")
def bundled_db() -> Path:
    """The Lensfun database installed with lensfunpy (the default of `lensaudit scan`)."""
    return bundled_database_path()


def lens_xml(
    *distortions: str, cropfactor: str | None = "1", extra: str = "", calibration: str = ""
) -> str:
    """A one-lens database whose calibration holds the given <distortion> lines."""
    crop = f"<cropfactor>{cropfactor}</cropfactor>" if cropfactor is not None else ""
    body = "\n            ".join(distortions)
    return textwrap.dedent(f"""\
        <lensdatabase version="2">
            <lens>
                <maker>Test</maker>
                <model>Test 10mm</model>
                <model lang="de">Testobjektiv 10mm</model>
                <mount>Test Mount</mount>
                {crop}
                {extra}
                <calibration{calibration}>
                    {body}
                </calibration>
            </lens>
        </lensdatabase>
        """)


@pytest.fixture
def write_xml(tmp_path: Path) -> Callable[..., Path]:
    """Write XML text (or bytes) to a file in a temporary database directory."""

    def write(content: str | bytes, name: str = "test.xml") -> Path:
        path = tmp_path / "db" / name
        path.parent.mkdir(exist_ok=True)
        if isinstance(content, str):
            content = content.encode("utf-8")
        path.write_bytes(content)
        return path

    return write


@pytest.fixture(scope="session")
def liblensfun_lenses() -> dict:
    """liblensfun's lenses of the bundled database, by (maker, model, crop factor).

    The crop factor is taken at single precision, as liblensfun keeps it, so
    that it matches lensaudit's value rounded the same way.
    """
    lensfunpy = pytest.importorskip("lensfunpy")
    import numpy as np

    found: dict = {}
    for lens in lensfunpy.Database().lenses:
        key = (lens.maker.strip(), lens.model.strip(), float(np.float32(lens.crop_factor)))
        found.setdefault(key, lens)
    return found


#: The Lensfun database's git history, beside the repository (absent in a user's clone).
HISTORY_BUNDLE = (
    Path(__file__).resolve().parents[2] / "shared" / "data" / "lensfun-db-history.bundle"
)


def clone_history(directory: Path, name: str = "lensfun", *options: str) -> Path:
    """A clone of Lensfun's history bundle, ``directory``/``name`` (git clone
    ``options``); skips the test without the bundle or git."""
    import shutil
    import subprocess

    if not HISTORY_BUNDLE.is_file():
        pytest.skip(
            f"no Lensfun history bundle at {HISTORY_BUNDLE} (../shared/data from the repository)"
        )
    if shutil.which("git") is None:
        pytest.skip("git is not installed")
    clone = directory / name
    try:
        subprocess.run(
            ["git", "clone", "--quiet", *options, str(HISTORY_BUNDLE), str(clone)],
            check=True,
            capture_output=True,
            timeout=600,
        )
    except (OSError, subprocess.SubprocessError) as error:
        pytest.skip(f"cannot clone the Lensfun history bundle: {error}")
    return clone


@pytest.fixture(scope="session")
def lensfun_head(tmp_path_factory) -> Path:
    """data/db at the last commit of Lensfun's history bundle; skips without the bundle."""
    return clone_history(tmp_path_factory.mktemp("head")) / "data" / "db"


@pytest.fixture(scope="session")
def lensfun_head_history(lensfun_head: Path):
    """``audit_history`` of the whole of Lensfun's history (the clone of
    :func:`lensfun_head`), made once for the tests that read it."""
    from lensaudit.history import audit_history

    return audit_history(lensfun_head.parents[1])


#: A one-lens database whose poly3 entry folds inside its image (line 10).
FOLDING_LENS = lens_xml('<distortion model="poly3" focal="16" k1="-0.11"/>')


@pytest.fixture
def folding_db(tmp_path: Path) -> Path:
    """A database directory holding :data:`FOLDING_LENS` as a.xml."""
    directory = tmp_path / "db"
    directory.mkdir()
    (directory / "a.xml").write_text(FOLDING_LENS)
    return directory


def git_repository(path: Path, files: dict[str, str]) -> Path:
    """A git repository at ``path`` with one commit of ``files`` (name -> text)."""
    import subprocess

    path.mkdir(parents=True, exist_ok=True)
    environment = {**os.environ, **GIT_ENVIRONMENT}
    subprocess.run(["git", "-C", str(path), "init", "-q"], check=True, env=environment)
    git_commit(path, files, "one")
    return path


def git_commit(repository: Path, files: dict[str, str], message: str, date: str = "") -> None:
    """Write ``files`` (name -> text) into ``repository`` and commit them
    (author and committer date ``date``, if given)."""
    import subprocess

    for name, text in files.items():
        (repository / name).parent.mkdir(parents=True, exist_ok=True)
        (repository / name).write_text(text)
    environment = {**os.environ, **GIT_ENVIRONMENT}
    if date:
        environment |= {"GIT_AUTHOR_DATE": date, "GIT_COMMITTER_DATE": date}
    for words in (["add", *files], ["commit", "-qm", message]):
        subprocess.run(["git", "-C", str(repository), *words], check=True, env=environment)


def no_child_left() -> bool:
    """Whether this process has no child process left (none running, none unreaped)."""
    try:
        os.waitpid(-1, os.WNOHANG)
    except ChildProcessError:
        return True
    return False


def ended_pid() -> int:
    """The id of a process that has ended (and been reaped): a temporary file
    named with it is abandoned."""
    import subprocess
    import sys

    done = subprocess.Popen([sys.executable, "-c", "pass"])
    done.wait()
    return done.pid


@pytest.fixture
def running_pid():
    """The id of another process, running for the test."""
    import subprocess
    import sys

    process = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    try:
        yield process.pid
    finally:
        process.kill()
        process.wait()
