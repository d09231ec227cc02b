"""`lensaudit check --baseline <parent>` replayed on commits of Lensfun's real history.

Each commit is checked against its first parent, as Lensfun's CI would, and
every failure is judged by scripts/replay_check.py's oracle: a failing
finding is justified only if it points into a <lens> block (or, for a
finding about a file, a file) that the commit's `git diff -U0` touches.

The commits: three that an earlier matching blamed for lenses they did not
touch (c6d214b and 5bb936c repair a file their parent broke, e7fb3bd only
renames a lens), the commits that broke those files, and the other kinds of
real mistakes in the last 300 commits (focal="0", a duplicated focal
length), with a commit on each side of every one of them.
"""

from __future__ import annotations

import contextlib
import importlib.util
import os
import pickle
import shutil
import sys
import traceback
from collections.abc import Callable
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
BUNDLE = ROOT.parent / "shared" / "data" / "lensfun-db-history.bundle"

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")
needs_history = pytest.mark.skipif(
    not BUNDLE.is_file(),
    reason=f"no Lensfun history bundle at {BUNDLE} (../shared/data from the repository)",
)

#: Commits the diff shows to be mistakes, and the finding each must fail with.
REAL_CATCHES = {
    "ebb76e8": "xml-error",  # slr-pentax.xml: a lens left unclosed
    "f8ee304": "xml-error",  # slr-tokina.xml: "--" inside a comment
    "44e316e": "xml-error",  # mil-canon.xml: </lens> missing
    "37b3b4e": "duplicate-focal",  # mil-canon.xml: two different 500 mm entries
    "f95fa20": "bad-value",  # slr-tokina.xml: focal="0"
}
#: Commits that change nothing a finding is about.
MUST_PASS = {
    "c6d214b": "repairs slr-tokina.xml; the Tokina 11-16 fold dates from 2012",
    "5bb936c": "repairs mil-canon.xml; its duplicate 500 mm entry was there before",
    "e7fb3bd": "renames Canon RF200-800mm to RF 200-800mm, duplicate entry unchanged",
}
#: Neighbours, so that each commit above is replayed in its window.
NEIGHBOURS = (
    "76b4afc",  # repairs slr-pentax.xml, broken by ebb76e8
    "5709184",
    "322006c",
    "b57cdc2",
    "b1725bd",
    "c153423",
    "b58144a",
    "0e35124",
    "4379cae",
    "44cbca5",
    "f70c0fe",
    "03d3b33",
)

#: Commits that add a lens twin of an existing one, above it in the file or
#: by a merge: the duplicate must be reported on the lens the commit added.
ADDED_TWINS = {
    "f206332": ("duplicate-lens", "mil-sigma.xml"),  # a second Sigma 19mm f/2.8 EX DN above
    "b73f02a": ("duplicate-lens", "slr-canon.xml"),  # a merge adds a second EF 50mm f/1.4
}
#: A commit whose baseline has a file liblensfun already refused (see its test).
REFUSAL_KNOWN = "04906284"


def load_replay():
    spec = importlib.util.spec_from_file_location(
        "replay_check", ROOT / "scripts" / "replay_check.py"
    )
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("replay_check", module)
    spec.loader.exec_module(module)
    return module


replay_check = load_replay()


@pytest.fixture(scope="module")
def history(lensfun_head) -> Path:
    """The session's clone of the Lensfun history bundle."""
    return lensfun_head.parents[1]


def beside(work: Callable[[], object]) -> Callable[[], object]:
    """Start ``work()`` in a forked process, where ``os.fork`` exists (else do
    it now), so that it runs while this process goes on; the function
    returned waits for it and returns what it returned."""
    if not hasattr(os, "fork"):
        done = work()
        return lambda: done
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: the work, its result (or its error) down the pipe, and out
        try:
            os.close(read_end)
            try:
                answer = (True, work())
            except BaseException:  # noqa: B036 - told to the parent, which raises it
                answer = (False, traceback.format_exc())
            with os.fdopen(write_end, "wb") as stream:
                pickle.dump(answer, stream)
        finally:
            os._exit(0)
    os.close(write_end)

    def wait() -> object:
        with os.fdopen(read_end, "rb") as stream:
            data = stream.read()
        os.waitpid(pid, 0)
        ok, value = pickle.loads(data) if data else (False, "the forked process died")
        assert ok, value
        return value

    return wait


@pytest.fixture(scope="module")
def replays(history, tmp_path_factory) -> tuple[dict, dict]:
    """(rows, cached rows) by the short ids used here: every commit named here
    replayed (the window's oldest first, then the others), and meanwhile, in
    a forked process, the window's again with lensaudit's cache, as a CI job
    keeping it would."""
    names = [*REAL_CATCHES, *MUST_PASS, *NEIGHBOURS]
    full = {name: replay_check.git(history, "rev-parse", name).decode().strip() for name in names}
    order = replay_check.window(history, None, None, ())  # the last 300, oldest first
    commits = [c for c in order if c in full.values()]
    assert len(commits) == len(names)
    cache = tmp_path_factory.mktemp("replay-cache")

    def cached() -> list[replay_check.Row]:
        with pytest.MonkeyPatch.context() as patch:
            patch.setenv("LENSAUDIT_CACHE_DIR", str(cache))
            return list(replay_check.replay(history, commits, cache=True))

    wait = beside(cached)
    others = [*ADDED_TWINS, REFUSAL_KNOWN]
    full |= {name: replay_check.git(history, "rev-parse", name).decode().strip() for name in others}
    short = {commit: name for name, commit in full.items()}
    try:
        rows = replay_check.replay(history, commits + [full[name] for name in others])
        found = {short[row.commit]: row for row in rows}
    except BaseException:
        with contextlib.suppress(BaseException):
            wait()  # no child outlives the fixture
        raise
    return found, {short[row.commit]: row for row in wait()}


@pytest.fixture(scope="module")
def replayed(replays) -> dict[str, replay_check.Row]:
    """The row of each commit named here, by the short id used here."""
    return replays[0]


@pytest.fixture(scope="module")
def verdicts(replayed) -> dict[str, replay_check.Row]:
    """Each replayed commit's row of the window, by the short id used above, oldest first."""
    return {
        name: row for name, row in replayed.items() if name not in [*ADDED_TWINS, REFUSAL_KNOWN]
    }


@pytest.fixture(scope="module")
def cached_verdicts(replays) -> dict[str, replay_check.Row]:
    """The window's commits replayed with lensaudit's cache, as a CI job keeping it would."""
    return replays[1]


@needs_history
def test_the_cache_changes_no_verdict_and_no_finding(verdicts, cached_verdicts):
    assert {name: (row.verdict, row.findings) for name, row in cached_verdicts.items()} == {
        name: (row.verdict, row.findings) for name, row in verdicts.items()
    }


@needs_history
def test_no_commit_of_the_window_is_blamed_for_what_it_did_not_change(verdicts):
    blamed = {name: row.findings for name, row in verdicts.items() if row.verdict != "pass"}
    assert not {n: f for n, f in blamed.items() if n not in REAL_CATCHES}
    assert all(row.verdict != replay_check.FALSE_BLAME for row in verdicts.values())


@needs_history
@pytest.mark.parametrize("commit", sorted(MUST_PASS))
def test_commit_that_changes_no_finding_passes(verdicts, commit):
    row = verdicts[commit]
    assert row.verdict == replay_check.PASS, (MUST_PASS[commit], row.findings)


@needs_history
@pytest.mark.parametrize("commit", sorted(REAL_CATCHES))
def test_real_mistake_still_fails_with_a_justified_finding(verdicts, commit):
    row = verdicts[commit]
    assert row.verdict == replay_check.FAIL_JUSTIFIED, row.findings
    assert [finding.split()[0] for finding in row.findings] == [REAL_CATCHES[commit]]


# -- the oracle itself, on hand-made input -----------------------------------------------

TEXT = b"""<lensdatabase>
  <lens>
    <model>A</model>
  </lens>
  <lens>
    <model>B</model>
  </lens>
</lensdatabase>
"""


def test_lens_blocks_are_found_from_the_text():
    assert replay_check.lens_blocks(TEXT) == [(2, 4), (5, 7)]


def test_an_unclosed_lens_block_runs_to_the_next_lens():
    assert replay_check.lens_blocks(TEXT.replace(b"  </lens>\n  <lens>", b"  <lens>", 1)) == [
        (2, 3),
        (4, 6),
    ]


def test_a_finding_in_an_untouched_block_is_not_justified():
    touched = {"db/a.xml": replay_check.Touched(lines={6})}
    blocks = {"db/a.xml": replay_check.lens_blocks(TEXT)}
    assert not replay_check.justified([("db/a.xml", 3)], False, touched, blocks)
    assert replay_check.justified([("db/a.xml", 7)], False, touched, blocks)


def test_a_deletion_inside_a_block_touches_it():
    touched = {"db/a.xml": replay_check.Touched(gaps={2})}
    blocks = {"db/a.xml": replay_check.lens_blocks(TEXT)}
    assert replay_check.justified([("db/a.xml", 3)], False, touched, blocks)
    assert not replay_check.justified([("db/a.xml", 6)], False, touched, blocks)


def test_a_finding_is_justified_by_its_own_place_not_by_another():
    touched = {"db/b.xml": replay_check.Touched(lines={1})}
    blocks = {"db/a.xml": replay_check.lens_blocks(TEXT), "db/b.xml": [(1, 3)]}
    assert replay_check.justified([("db/b.xml", 2)], False, touched, blocks)
    assert not replay_check.justified([("db/a.xml", 3)], False, touched, blocks)


@needs_history
@pytest.mark.parametrize("commit", sorted(ADDED_TWINS))
def test_a_duplicate_points_at_the_lens_the_commit_added(replayed, commit):
    row = replayed[commit]
    assert row.verdict == replay_check.FAIL_JUSTIFIED, row.findings
    code, name = ADDED_TWINS[commit]
    assert any(f.startswith(f"{code} {name}:") for f in row.findings), row.findings


def test_a_file_level_finding_is_justified_by_any_change_to_its_file():
    touched = {"db/a.xml": replay_check.Touched(lines={8})}
    blocks = {"db/a.xml": replay_check.lens_blocks(TEXT)}
    assert replay_check.justified([("db/a.xml", 3)], True, touched, blocks)
    assert not replay_check.justified([("db/c.xml", 3)], True, touched, blocks)


@needs_history
def test_a_refusal_the_broken_baseline_file_had_is_known(replayed):
    """04906284 adds a Fujifilm X20 to another file; compact-sony.xml was
    already not well-formed, and liblensfun already stopped reading it at
    line 774: the baseline file replaced by its last readable version still
    counts both of its file-level findings."""
    row = replayed[REFUSAL_KNOWN]
    assert row.verdict == replay_check.PASS, row.findings
