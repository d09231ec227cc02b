"""The release: `python -m build` makes an sdist and a wheel that twine accepts.

The project is copied to a temporary directory first, so that building never
writes into the checkout. The wheel is built from the sdist, as `python -m
build` does, which also proves that the sdist holds everything it needs.
Expected file lists come from the source tree, not from the build.
"""

from __future__ import annotations

import email.parser
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "lensaudit"

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("build") is None,
    reason="`build` is not installed (pip install '.[test]' brings it)",
)

#: Never copied: caches, virtual environments and earlier builds.
SKIPPED_IN_COPY = shutil.ignore_patterns(
    ".git", ".ci", ".venv", "build", "dist", "*.egg-info", "__pycache__", ".*cache", ".hypothesis"
)


@pytest.fixture(scope="module")
def built(tmp_path_factory) -> dict[str, Path]:
    """{"sdist": path, "wheel": path}, built from a copy of the project."""
    base = tmp_path_factory.mktemp("packaging")
    source = base / "lensaudit"
    shutil.copytree(ROOT, source, symlinks=True, ignore=SKIPPED_IN_COPY)
    completed = subprocess.run(
        [sys.executable, "-m", "build", "--outdir", str(base / "dist"), str(source)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert completed.returncode == 0, completed.stdout[-3000:] + completed.stderr[-3000:]
    (sdist,) = (base / "dist").glob("lensaudit-*.tar.gz")
    (wheel,) = (base / "dist").glob("lensaudit-*.whl")
    return {"sdist": sdist, "wheel": wheel}


def wheel_names(wheel: Path) -> set[str]:
    with zipfile.ZipFile(wheel) as archive:
        return set(archive.namelist())


def wheel_metadata(wheel: Path):
    with zipfile.ZipFile(wheel) as archive:
        (name,) = [n for n in archive.namelist() if n.endswith(".dist-info/METADATA")]
        return email.parser.Parser().parsestr(archive.read(name).decode("utf-8"))


@pytest.mark.skipif(importlib.util.find_spec("twine") is None, reason="twine is not installed")
def test_twine_accepts_the_sdist_and_the_wheel(built):
    completed = subprocess.run(
        [
            sys.executable,
            "-m",
            "twine",
            "check",
            "--strict",
            str(built["sdist"]),
            str(built["wheel"]),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert completed.returncode == 0, completed.stdout + completed.stderr


def test_wheel_holds_every_module_of_the_package(built):
    expected = {
        f"lensaudit/{path.relative_to(PACKAGE).as_posix()}"
        for path in PACKAGE.rglob("*.py")
        if "__pycache__" not in path.parts
    }
    assert expected <= wheel_names(built["wheel"])


def test_wheel_holds_the_package_data(built):
    data = {f"lensaudit/data/{path.name}" for path in (PACKAGE / "data").glob("*.json")}
    assert data, "src/lensaudit/data has no JSON file to install"
    assert data | {"lensaudit/py.typed"} <= wheel_names(built["wheel"])


def test_wheel_holds_nothing_but_the_package_and_its_metadata(built):
    names = wheel_names(built["wheel"])
    outside = {n for n in names if not n.startswith(("lensaudit/", "lensaudit-"))}
    assert outside == set()
    assert not [n for n in names if "tests/" in n or "reports/" in n or "conftest" in n]
    assert not [n for n in names if n.endswith((".pyc", ".csv", ".html", ".png", ".svg"))]


def test_wheel_metadata_declares_the_license_readme_and_command(built):
    metadata = wheel_metadata(built["wheel"])
    assert metadata["License-Expression"] == "MIT"
    assert metadata["Description-Content-Type"] == "text/markdown"
    assert metadata.get_payload().startswith("# lensaudit")
    with zipfile.ZipFile(built["wheel"]) as archive:
        licenses = [n for n in archive.namelist() if n.endswith("/licenses/LICENSE")]
        assert licenses
        assert archive.read(licenses[0]) == (ROOT / "LICENSE").read_bytes()
        (entry_points,) = [n for n in archive.namelist() if n.endswith("entry_points.txt")]
        assert "lensaudit = lensaudit.console:run" in archive.read(entry_points).decode()


def test_lensfunpy_is_a_range_not_one_version(built):
    requirements = wheel_metadata(built["wheel"]).get_all("Requires-Dist")
    (lensfunpy,) = [r for r in requirements if r.startswith("lensfunpy")]
    assert "==" not in lensfunpy and ">=" in lensfunpy


def test_sdist_holds_the_license_and_the_whole_test_suite(built):
    with tarfile.open(built["sdist"]) as archive:
        names = {name.split("/", 1)[1] for name in archive.getnames() if "/" in name}
    tests = {f"tests/{path.name}" for path in (ROOT / "tests").glob("*.py")}
    assert {"LICENSE", "README.md", "pyproject.toml"} <= names
    assert tests <= names


# --- the GitHub Actions workflow of docs/ci.md ---------------------------------------------

CI_DOC = ROOT / "docs" / "ci.md"
ZERO = "0" * 40
needs_git_and_bash = pytest.mark.skipif(
    not (shutil.which("git") and shutil.which("bash")), reason="needs git and bash"
)


def workflow_text() -> str:
    """The YAML block of the section "GitHub Actions" of docs/ci.md."""
    section = CI_DOC.read_text(encoding="utf-8").split("## GitHub Actions", 1)[1]
    return section.split("```yaml\n", 1)[1].split("```", 1)[0]


def workflow_step_script(step_marker: str) -> str:
    """The `run:` script of the step whose lines include step_marker."""
    lines = workflow_text().splitlines()
    start = next(i for i, line in enumerate(lines) if step_marker in line)
    run = next(i for i in range(start, len(lines)) if lines[i].strip().startswith("run:"))
    inline = lines[run].split("run:", 1)[1].strip()
    if inline != "|":
        return inline
    indent = len(lines[run]) - len(lines[run].lstrip()) + 2
    body = []
    for line in lines[run + 1 :]:
        if line.strip() and len(line) - len(line.lstrip()) < indent:
            break
        body.append(line[indent:])
    return "\n".join(body) + "\n"


def git(repo: Path, *arguments: str) -> str:
    environment = {
        "GIT_AUTHOR_NAME": "t",
        "GIT_AUTHOR_EMAIL": "t@example.org",
        "GIT_COMMITTER_NAME": "t",
        "GIT_COMMITTER_EMAIL": "t@example.org",
        "GIT_CONFIG_GLOBAL": "/dev/null",
        "GIT_CONFIG_NOSYSTEM": "1",
        "PATH": os.environ.get("PATH", ""),
        "HOME": str(repo),
    }
    completed = subprocess.run(
        ["git", "-C", str(repo), *arguments], capture_output=True, text=True, env=environment
    )
    assert completed.returncode == 0, completed.stderr
    return completed.stdout.strip()


def scratch_repository(path: Path, *databases: str) -> list[str]:
    """A git repository with one commit per database text (data/db/test.xml); their ids."""
    path.mkdir()
    git(path, "init", "-q", "-b", "master")
    commits = []
    for number, text in enumerate(databases):
        (path / "data" / "db").mkdir(parents=True, exist_ok=True)
        (path / "data" / "db" / "test.xml").write_text(text, encoding="utf-8")
        git(path, "add", "data/db/test.xml")
        git(path, "commit", "-q", "-m", f"commit {number}")
        commits.append(git(path, "rev-parse", "HEAD"))
    return commits


def choose_baseline(repo: Path, tmp_path: Path, **event: str) -> str:
    """Run the workflow's baseline step in repo; the baseline it writes to GITHUB_OUTPUT."""
    output = tmp_path / "github_output"
    output.write_text("")
    environment = {
        "PATH": os.environ.get("PATH", ""),
        "GITHUB_OUTPUT": str(output),
        "EVENT": event.get("EVENT", ""),
        "BASE_REF": event.get("BASE_REF", ""),
        "BEFORE": event.get("BEFORE", ""),
    }
    completed = subprocess.run(
        ["bash", "-e", "-c", workflow_step_script("id: baseline")],
        cwd=repo,
        capture_output=True,
        text=True,
        env=environment,
    )
    assert completed.returncode == 0, completed.stderr
    (line,) = output.read_text().splitlines()
    assert line.startswith("baseline=")
    return line.removeprefix("baseline=")


def test_workflow_keeps_the_cache_directory_lensaudit_uses_on_a_runner(monkeypatch, tmp_path):
    from lensaudit.read.cache import cache_dir

    path = re.search(r"uses: actions/cache@v\d+\n\s+with:\n\s+path: (\S+)", workflow_text())
    assert path
    monkeypatch.setenv("HOME", str(tmp_path))  # a runner: no $XDG_CACHE_HOME, no override
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.delenv("LENSAUDIT_CACHE_DIR", raising=False)
    assert cache_dir() == Path(path[1].replace("~", str(tmp_path), 1))


def test_workflow_runs_on_push_and_on_pull_request():
    text = workflow_text()
    triggers = text.split("\non:\n", 1)[1].split("\njobs:", 1)[0]
    events = {line.strip().rstrip(":") for line in triggers.splitlines() if line[2:3].isalpha()}
    assert events == {"push", "pull_request"}


@needs_git_and_bash
def test_workflow_baseline_of_a_pull_request_is_its_base_branch(tmp_path):
    scratch_repository(tmp_path / "repo", "<lensdatabase/>")
    baseline = choose_baseline(tmp_path / "repo", tmp_path, EVENT="pull_request", BASE_REF="main")
    assert baseline == "origin/main"


@needs_git_and_bash
def test_workflow_baseline_of_a_push_is_the_commit_before_it(tmp_path):
    first, _, _ = scratch_repository(tmp_path / "repo", "<a/>", "<b/>", "<c/>")
    assert choose_baseline(tmp_path / "repo", tmp_path, EVENT="push", BEFORE=first) == first


@needs_git_and_bash
def test_workflow_baseline_of_a_new_branch_is_the_parent_commit(tmp_path):
    scratch_repository(tmp_path / "repo", "<a/>", "<b/>")
    assert choose_baseline(tmp_path / "repo", tmp_path, EVENT="push", BEFORE=ZERO) == "HEAD~1"


@needs_git_and_bash
def test_workflow_baseline_after_a_force_push_is_the_parent_commit(tmp_path):
    scratch_repository(tmp_path / "repo", "<a/>", "<b/>")
    gone = "1234567890abcdef1234567890abcdef12345678"  # a commit the clone does not have
    assert choose_baseline(tmp_path / "repo", tmp_path, EVENT="push", BEFORE=gone) == "HEAD~1"


@needs_git_and_bash
def test_workflow_has_no_baseline_for_the_first_commit(tmp_path):
    scratch_repository(tmp_path / "repo", "<a/>")
    assert choose_baseline(tmp_path / "repo", tmp_path, EVENT="push", BEFORE=ZERO) == ""


@needs_git_and_bash
@pytest.mark.parametrize(("baseline", "status"), [("", 1), ("HEAD~1", 1), ("HEAD", 0)])
def test_workflow_check_step_fails_only_on_what_the_baseline_lacks(tmp_path, baseline, status):
    from conftest import lens_xml

    # poly3 with k1 = -0.3 folds at r = sqrt(1.3 / 0.9), D = 1.04: inside the 3:2 corner.
    folding = lens_xml('<distortion model="poly3" focal="10" k1="-0.3"/>')
    scratch_repository(tmp_path / "repo", lens_xml(), folding)
    environment = {
        **os.environ,
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
        "BASELINE": baseline,
        "LENSAUDIT_CACHE_DIR": str(tmp_path / "cache"),
    }
    completed = subprocess.run(
        ["bash", "-e", "-c", workflow_step_script("name: lensaudit check")],
        cwd=tmp_path / "repo",
        capture_output=True,
        text=True,
        env=environment,
        timeout=120,
    )
    assert completed.returncode == status, completed.stdout + completed.stderr
    assert ("::error file=data/db/test.xml" in completed.stdout) == (status == 1)
