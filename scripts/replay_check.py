#!/usr/bin/env python
"""Replay `lensaudit check` over a Lensfun history, as Lensfun's CI would run it.

    python scripts/replay_check.py /tmp/lensfun-db                  # last 300 commits
    python scripts/replay_check.py /tmp/lensfun-db --last 50
    python scripts/replay_check.py /tmp/lensfun-db v0.3.2..v0.3.3   # a revision range
    python scripts/replay_check.py /tmp/lensfun-db --commits c6d214b 5bb936c

For each commit C of the window (by default the last 300 first-parent
commits that touch data/db; merges are compared with their first parent),
the database of C is checked against its parent P, like
`lensaudit check data/db --baseline P` in a checkout of C. A separate,
shared clone in a temporary directory is checked out commit by commit (only
data/db), so the repository given is never touched.

Every new failing finding is then judged by an oracle that knows nothing of
how the check matches entries: the finding is justified only if the line it
points at lies in a top-level <lens> block in which `git diff -U0 P C`
changed a line (context lines do not count), or, for a finding about a
whole file (or a line outside any <lens>), in a file the diff touches. A
finding about two entries or two lenses is judged by its own line, not by
its twin's: GitHub shows an annotation inline only on lines the pull
request changed, so a duplicate must point at the one the change added.
Lens blocks are found by scanning the text for <lens ...> and </lens>, so
they are known also in a file that is not well-formed.

Verdicts: pass (no failing finding), fail-justified (every failing finding
is justified), fail-FALSE-BLAME (at least one is not; it is marked with !),
error (the check could not run). Exit status: 0 when no commit is falsely
blamed, 1 otherwise, 2 bad usage.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from lensaudit.check import check  # noqa: E402
from lensaudit.read import LoadError  # noqa: E402

#: Where a Lensfun repository keeps its database.
DB_DIR = "data/db"
DEFAULT_LAST = 300

PASS = "pass"
FAIL_JUSTIFIED = "fail-justified"
FALSE_BLAME = "fail-FALSE-BLAME"
ERROR = "error"

#: Findings about a whole file rather than a line of it.
FILE_LEVEL_CODES = frozenset({"xml-error", "unreadable", "not-a-database"})

_GIT_ENVIRONMENT = {"GIT_OPTIONAL_LOCKS": "0", "GIT_TERMINAL_PROMPT": "0", "LC_ALL": "C"}
_HUNK = re.compile(rb"^@@ -\d+(?:,\d+)? \+(\d+)(?:,(\d+))? @@", re.MULTILINE)
_LENS_OPEN = re.compile(rb"<lens[\s>/]")
_LENS_CLOSE = re.compile(rb"</lens\s*>")


def git(repository: Path, *arguments: str) -> bytes:
    """Output of a git command; raises CalledProcessError on failure."""
    return subprocess.run(
        ["git", *arguments],
        cwd=repository,
        capture_output=True,
        check=True,
        env={**os.environ, **_GIT_ENVIRONMENT},
    ).stdout


# ---------------------------------------------------------------------------
# The oracle: what a commit touched


@dataclass
class Touched:
    """What the diff of a commit against its parent touches in one file.

    ``lines`` are line numbers of the commit's version that were added or
    changed; ``gaps`` are lines after which something was deleted.
    """

    lines: set[int] = field(default_factory=set)
    gaps: set[int] = field(default_factory=set)


def touched_files(repository: Path, parent: str, commit: str) -> dict[str, Touched]:
    """Per file (path from the repository root), what ``git diff -U0`` touches."""
    output = git(
        repository, "diff", "-U0", "--no-color", "--no-ext-diff", parent, commit, "--", DB_DIR
    )
    touched: dict[str, Touched] = {}
    current: Touched | None = None
    for part in re.split(rb"^diff --git ", output, flags=re.MULTILINE)[1:]:
        names = re.search(rb"^\+\+\+ (?:b/(.*)|/dev/null)$", part, re.MULTILINE)
        old = re.search(rb"^--- (?:a/(.*)|/dev/null)$", part, re.MULTILINE)
        if names and names.group(1):
            name = names.group(1)
        elif old and old.group(1):
            name = old.group(1)  # deleted: nothing of the commit's version to point at
        else:
            header = part.split(b"\n", 1)[0]  # binary or mode-only change: "a/x b/x"
            name = header.rsplit(b" b/", 1)[-1]
        current = touched.setdefault(os.fsdecode(name), Touched())
        for match in _HUNK.finditer(part):
            start = int(match.group(1))
            count = 1 if match.group(2) is None else int(match.group(2))
            if count:
                current.lines.update(range(start, start + count))
            else:
                current.gaps.add(start)
    return touched


def lens_blocks(data: bytes) -> list[tuple[int, int]]:
    """(first, last) line of every <lens> ... </lens> block, found in the text.

    A block that is never closed runs to the next <lens> or the end of the file.
    """
    events = sorted(
        [(m.start(), 0) for m in _LENS_OPEN.finditer(data)]
        + [(m.end() - 1, 1) for m in _LENS_CLOSE.finditer(data)]
    )
    blocks: list[tuple[int, int]] = []
    start: int | None = None
    for offset, kind in events:
        line = data.count(b"\n", 0, offset) + 1
        if kind == 0:
            if start is not None:
                blocks.append((start, line - 1))
            start = line
        elif start is not None:
            blocks.append((start, line))
            start = None
    if start is not None:
        blocks.append((start, data.count(b"\n") + 1))
    return blocks


def justified(
    locations: Iterable[tuple[str, int]],
    file_level: bool,
    touched: dict[str, Touched],
    blocks: dict[str, list[tuple[int, int]]],
) -> bool:
    """True when one of ``locations`` (file from the repository root, line)
    lies in a <lens> block the diff touches, or, for a finding about a whole
    file or a line outside every block, in a file the diff touches."""
    for name, line in locations:
        if name not in touched:
            continue
        block = next((b for b in blocks.get(name, []) if b[0] <= line <= b[1]), None)
        if file_level or line <= 0 or block is None:
            return True
        first, last = block
        change = touched[name]
        if any(first <= n <= last for n in change.lines) or any(
            first <= n < last for n in change.gaps
        ):
            return True
    return False


# ---------------------------------------------------------------------------
# Replaying commits


@dataclass
class Row:
    """The verdict on one commit."""

    commit: str
    subject: str
    verdict: str
    findings: list[str]
    seconds: float


def window(
    repository: Path, last: int | None, revisions: str | None, commits: Sequence[str]
) -> list[str]:
    """Commit ids to replay, oldest first."""
    if commits:
        return [
            git(repository, "rev-parse", "--verify", f"{c}^{{commit}}").decode().strip()
            for c in commits
        ]
    # --max-count applies before --reverse: the newest N, listed oldest first.
    arguments = ["rev-list", "--first-parent", "--reverse"]
    if last or revisions is None:
        arguments.append(f"--max-count={last or DEFAULT_LAST}")
    arguments.append(revisions or "HEAD")
    return git(repository, *arguments, "--", DB_DIR).decode().split()


def _repository_path(worktree: Path, display: str) -> str:
    path = Path(display)
    if not path.is_absolute():
        path = Path.cwd() / path
    try:
        return path.resolve().relative_to(worktree.resolve()).as_posix()
    except ValueError:
        return display


def judge(
    worktree: Path, commit: str, parent: str, margin: float = 1.1, cache: bool = False
) -> tuple[str, list[str]]:
    """Check ``commit``, checked out in the git work tree ``worktree``, against
    ``parent`` (with lensaudit's cache if ``cache``): the verdict and the
    failing findings (``!`` marks one that the diff does not justify)."""
    try:
        result = check(worktree / DB_DIR, baseline=parent, margin=margin, cache=cache)
    except LoadError as error:
        return ERROR, [str(error)]
    failing = [f for f in result.findings if f.fails]
    if not failing:
        return PASS, []
    touched = touched_files(worktree, parent, commit)
    blocks: dict[str, list[tuple[int, int]]] = {}
    for name in touched:
        try:
            blocks[name] = lens_blocks((worktree / name).read_bytes())
        except OSError:
            blocks[name] = []
    verdict = FAIL_JUSTIFIED
    described = []
    for finding in failing:
        # Its own line only: the twin of a duplicate is where the annotation is not.
        locations = [(_repository_path(worktree, finding.file), finding.line)]
        ok = justified(locations, finding.code in FILE_LEVEL_CODES, touched, blocks)
        if not ok:
            verdict = FALSE_BLAME
        where = f"{locations[0][0].removeprefix(DB_DIR + '/')}:{locations[0][1]}"
        described.append(f"{'' if ok else '!'}{finding.code} {where}")
    return verdict, described


def replay(
    repository: Path, commits: Sequence[str], margin: float = 1.1, cache: bool = False
) -> Iterator[Row]:
    """Check each commit against its first parent in a temporary shared clone
    (with lensaudit's cache if ``cache``: each commit then parses only the
    files it changed)."""
    with tempfile.TemporaryDirectory(prefix="lensaudit-replay-") as temporary:
        worktree = Path(temporary) / "lensfun"
        git(
            repository,
            "clone",
            "--quiet",
            "--shared",
            "--no-checkout",
            str(repository),
            str(worktree),
        )
        git(worktree, "sparse-checkout", "set", "--no-cone", f"/{DB_DIR}/")
        for commit in commits:
            started = time.perf_counter()
            subject = git(worktree, "log", "-1", "--format=%s", commit).decode().strip()
            parents = git(worktree, "rev-list", "--parents", "-1", commit).decode().split()[1:]
            if not parents:
                continue  # the first commit has nothing to compare with
            git(worktree, "checkout", "--quiet", "--force", "--detach", commit)
            verdict, findings = judge(worktree, commit, parents[0], margin, cache)
            yield Row(commit, subject, verdict, findings, time.perf_counter() - started)


def totals(rows: Sequence[Row]) -> dict[str, int]:
    """Commits per verdict."""
    counts = dict.fromkeys((PASS, FAIL_JUSTIFIED, FALSE_BLAME, ERROR), 0)
    for row in rows:
        counts[row.verdict] += 1
    return counts


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("repository", type=Path, help="a clone of Lensfun's history")
    parser.add_argument("range", nargs="?", help="revision range, e.g. A..B (first parents)")
    parser.add_argument("--last", type=int, help=f"the last N commits (default {DEFAULT_LAST})")
    parser.add_argument("--commits", nargs="+", default=(), help="exactly these commits")
    parser.add_argument("--margin", type=float, default=1.1)
    parser.add_argument("--all", action="store_true", help="list passing commits too")
    parser.add_argument(
        "--cache",
        action="store_true",
        help="use lensaudit's cache, as a CI job that keeps it would (faster)",
    )
    args = parser.parse_args(argv)
    try:
        commits = window(args.repository, args.last, args.range, args.commits)
    except (subprocess.CalledProcessError, OSError) as error:
        stderr = getattr(error, "stderr", b"") or b""
        message = stderr.decode(errors="replace").strip() or str(error)
        print(f"replay_check: error: {message}", file=sys.stderr)
        return 2
    rows = []
    started = time.perf_counter()
    print(f"{'commit':8}  {'verdict':16}  {'subject':50}  findings")
    for row in replay(args.repository, commits, args.margin, args.cache):
        rows.append(row)
        if row.verdict != PASS or args.all:
            subject = row.subject if len(row.subject) <= 50 else row.subject[:49] + "\u2026"
            print(
                f"{row.commit[:8]}  {row.verdict:16}  {subject:50}  {'; '.join(row.findings)}",
                flush=True,
            )
    seconds = time.perf_counter() - started
    counts = totals(rows)
    print(
        f"{len(rows)} commits: "
        + ", ".join(f"{count} {verdict}" for verdict, count in counts.items())
        + f"; {seconds:.1f} s ({seconds / max(len(rows), 1):.2f} s per commit)"
    )
    return 1 if counts[FALSE_BLAME] else 0


if __name__ == "__main__":
    raise SystemExit(main())
