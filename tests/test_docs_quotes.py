"""Counts, file lists and output excerpts quoted in README.md, docs/report.md,
docs/history.md and docs/ci.md, held to a live run: of the bundled database,
or of the Lensfun history bundle (skipped without it). Timings are not held
here: the docs quote them only from docs/benchmarks.md."""

from __future__ import annotations

import csv
import io
import math
import re
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from conftest import clone_history
from lensaudit.cli import main

ROOT = Path(__file__).resolve().parents[1]
BUNDLE = ROOT.parent / "shared" / "data" / "lensfun-db-history.bundle"
NUMBER_WORDS = {"two": 2, "three": 3, "four": 4, "five": 5, "six": 6, "seven": 7}


def doc(name: str) -> str:
    return (ROOT / name).read_text(encoding="utf-8")


def block_after(text: str, command: str) -> list[str]:
    """The lines of the fenced block that follow ``$ command``, up to the next ``$`` or fence."""
    start = text.index(f"$ {command}\n") + len(f"$ {command}\n")
    lines = []
    for line in text[start:].splitlines():
        if line.startswith(("$ ", "```")):
            break
        lines.append(line)
    return lines


# --------------------------------------------------------------- README: scan


@pytest.fixture(scope="module")
def scan_output(bundled_db) -> list[str]:
    result = CliRunner().invoke(main, ["scan"])
    assert result.exit_code == 0, result.output
    return result.output.splitlines()


def test_readme_scan_excerpt_is_todays_output(scan_output):
    quoted = block_after(doc("README.md"), "lensaudit scan")
    # The first line names the installed database's path: only its start is quoted as is.
    assert scan_output[0].startswith(quoted[0].split("(")[0])
    assert quoted[1:] == scan_output[1:]


def test_readme_prose_counts_the_folds_of_the_live_scan(scan_output):
    line = next(x for x in scan_output if x.startswith("Entries that fold inside"))
    folds = int(line.rsplit(":", 1)[1])
    paper = int(re.search(r"(\d+) rectilinear entries would be flagged", "\n".join(scan_output))[1])
    readme = doc("README.md")
    word = re.search(r"\n(\w+) fold inside the very image", readme)[1].lower()
    assert NUMBER_WORDS[word] == folds
    units = re.search(r"\((\d+) rectilinear\s+entries against the paper's (\d+)\)", readme)
    assert (int(units[1]), int(units[2])) == (folds, paper)


def test_readme_command_table_names_each_commands_arguments_as_its_usage_does():
    import click

    context = click.Context(main)
    rows = re.findall(r"^\| `lensaudit (\w+)([^`]*)` \|", doc("README.md"), flags=re.M)
    assert {name for name, _ in rows} == set(main.list_commands(context))
    for name, words in rows:
        command = main.get_command(context, name)
        metavars = [p.metavar for p in command.params if isinstance(p, click.Argument)]
        # What the row names as arguments: upper-case words not taken by an option.
        named = re.sub(r"--?[\w-]+ [A-Z]+", "", words.replace("\\|", "|"))
        for word in re.findall(r"\[?[A-Z]+(?: \.\.\.)?\]?", named):
            assert word in metavars, (name, word, metavars)


# ------------------------------------------------------------ docs/report.md


@pytest.fixture(scope="module")
def report_runs(bundled_db, tmp_path_factory) -> tuple[str, str, list[str]]:
    """(first run's output, second run's, the files written), run as the doc shows."""
    out = tmp_path_factory.mktemp("report") / "out"
    first = CliRunner().invoke(main, ["report", "-o", str(out)])
    assert first.exit_code == 0, first.output
    second = CliRunner().invoke(main, ["report", "-o", str(out)])
    assert second.exit_code == 2
    shown = [text.replace(str(out), "out") for text in (first.output, second.output.strip())]
    return shown[0], shown[1], sorted(p.name for p in out.iterdir())


def test_report_excerpt_is_todays_output(report_runs):
    first, second, _ = report_runs
    quoted = block_after(doc("docs/report.md"), "lensaudit report -o out")
    live = re.sub(r"\(/\S*lensfunpy/db_files\)", "(.../lensfunpy/db_files)", first)
    assert quoted[:3] == live.splitlines()
    text = doc("docs/report.md")
    after = text.index("$ lensaudit report -o out", text.index("$ lensaudit report -o out") + 1)
    assert text[after:].splitlines()[1] == second


def test_report_counts_the_files_it_writes(report_runs):
    first, second, written = report_runs
    assert f"Wrote {len(written)} files" in first
    listed = second.split("already holds ")[1].split(";")[0].split(", ")
    assert sorted(listed) == written
    table = doc("docs/report.md").split("What DIR receives:")[1].split("\n\n")[1]
    named = set()
    for cell in re.findall(r"^\| (.+?) \|", table, flags=re.M)[2:]:
        for name in re.findall(r"`([^`]+)`", cell):
            named.add(name)
    # `.svg` beside fig5_r_normalized.png names fig5_r_normalized.svg.
    expanded = {n if not n.startswith(".") else "fig5_r_normalized" + n for n in named}
    assert set(written) <= expanded
    assert expanded - set(written) == {"paper_comparison.md"}  # with --paper only


def test_report_md_plot_query_excerpts_are_todays_output(bundled_db, tmp_path, monkeypatch):
    import shlex

    monkeypatch.chdir(tmp_path)  # not in a Lensfun checkout: the bundled database
    text = doc("docs/report.md")
    commands = re.findall(r"^\$ (lensaudit plot curve .+)$", text, flags=re.M)
    assert len(commands) == 2
    for command, status in zip(commands, (2, 0), strict=True):
        result = CliRunner().invoke(main, shlex.split(command)[1:])
        assert result.exit_code == status, result.output
        live = re.sub(r"\(/\S*lensfunpy/db_files\)", "(.../lensfunpy/db_files)", result.output)
        assert block_after(text, command) == live.splitlines()


# ----------------------------------------------------------- docs/history.md


@pytest.fixture(scope="module")
def lensfun_history_run(tmp_path_factory) -> tuple[list[str], Path]:
    """`lensaudit history` of the Lensfun bundle's clone: (output lines, output directory)."""
    base = tmp_path_factory.mktemp("lensfun-history")
    clone = clone_history(base, "lensfun-db")
    out = base / "history-out"
    result = CliRunner().invoke(main, ["history", str(clone), "-o", str(out), "--no-cache"])
    assert result.exit_code == 0, result.output
    return [line.replace(str(clone), "/tmp/lensfun-db") for line in result.output.splitlines()], out


def rows(path: Path) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(path.read_text(encoding="utf-8"))))


def test_history_excerpt_is_todays_output_but_the_time(lensfun_history_run):
    lines, _ = lensfun_history_run
    quoted = block_after(
        doc("docs/history.md"), "lensaudit history /tmp/lensfun-db -o history-out --no-cache"
    )
    untimed = [re.sub(r"; [\d.]+ s$", "", line) for line in quoted[:3]]
    assert untimed == [re.sub(r"; [\d.]+ s$", "", line) for line in lines[:3]]
    assert re.match(r"wrote history-out/history\.csv, .*trend\.svg$", quoted[3])
    commits = re.search(r"cloned \(([\d,]+) commits\)", doc("docs/history.md"))[1]
    assert lines[0].split(": ")[1].startswith(f"{commits} commits")


def test_history_csv_row_of_the_paper_snapshot_is_quoted_as_written(lensfun_history_run):
    _, out = lensfun_history_run
    text = doc("docs/history.md")
    header, row = text.split("```\ncommit,date,")[1].split("```")[0].strip().splitlines()
    live = (out / "history.csv").read_text(encoding="utf-8").splitlines()
    assert live[0] == "commit,date," + header
    assert row in live
    counts = rows(out / "history.csv")[live.index(row) - 1]
    quoted = re.search(r"(\d+) ptlens, (\d+)\s+poly3\s+and (\d+) poly5", text)
    assert quoted.groups() == (counts["ptlens"], counts["poly3"], counts["poly5"])
    finite = re.search(r"lensaudit finds\s+(\d+) in this revision", text)[1]
    assert finite == counts["finite"]


def test_history_per_revision_table_is_read_from_history_csv(lensfun_history_run):
    _, out = lensfun_history_run
    by_commit = {r["commit"][:7]: r for r in rows(out / "history.csv")}
    table = doc("docs/history.md").split("| state at | commit |")[1].split("\n\n")[0]
    quoted = re.findall(r"^\| ([\d-]+) \| (\w{7}) \| (.+) \|$", table, flags=re.M)
    assert len(quoted) >= 5
    for _, commit, cells in quoted:
        live = by_commit[commit]
        audited, finite, share, folds, paper = (c.strip() for c in cells.split("|"))
        assert live["mainline"] == "true"
        assert (audited, finite) == (live["audited"], live["finite"])
        assert share == f"{100 * float(live['share_finite']):.1f}%"
        assert folds == f"{live['folds_in_image']} / {live['folds_in_image_rectilinear']}"
        assert paper == live["folds_in_image_paper_units_rectilinear"]


def test_history_counts_the_commits_holding_a_broken_file(lensfun_history_run):
    _, out = lensfun_history_run
    broken = [r for r in rows(out / "history.csv") if int(r["files_with_errors"])]
    word = re.search(r"(\S+) commits hold a file that is not well-formed", doc("docs/history.md"))
    tens = {"Thirty": 30, "Twenty": 20, "Forty": 40}
    first, _, second = word[1].partition("-")
    assert tens[first] + (NUMBER_WORDS[second] if second else 0) == len(broken)
    assert broken[0]["commit"][:7] in doc("docs/history.md")


def test_history_table_of_todays_folds_is_introduced_csv(lensfun_history_run):
    _, out = lensfun_history_run
    folds = [r for r in rows(out / "introduced.csv") if r["folds_in_image"] == "true"]
    text = doc("docs/history.md")
    table = text.split("| file | lens | type | focal |")[1].split("\n\n")[0]
    quoted = re.findall(r"^\| (\S+\.xml) \| (.+) \|$", table, flags=re.M)
    assert len(quoted) == len(folds)
    word = re.search(r"The (\w+) entries that fold inside their own image today", text)[1]
    assert NUMBER_WORDS[word] == len(folds)
    live = {
        (r["file"], r["lens"]): (
            r["type"],
            f"{float(r['focal']):g}",
            f"{float(r['r_normalized']):.3f}",
            f"{float(r['r_normalized_paper']):.3f}",
            r["commit"][:7],
            r["date"][:10],
            r["author"],
        )
        for r in folds
    }
    for file, cells in quoted:
        lens, *values = (c.strip() for c in cells.split("|"))
        assert tuple(values) == live[(file, lens)]


def test_ci_md_counts_todays_folds(lensfun_history_run):
    _, out = lensfun_history_run
    folds = [r for r in rows(out / "introduced.csv") if r["folds_in_image"] == "true"]
    quoted = re.search(r"brought all (\d+) entries that fold", doc("docs/ci.md"))
    assert int(quoted[1]) == len(folds)


# ------------------------------------------------------- docs/ci.md's examples


@pytest.fixture(scope="module")
def lensfun_checkout(tmp_path_factory) -> Path:
    """A clone of the Lensfun history bundle to change, as docs/ci.md's examples do."""
    return clone_history(tmp_path_factory.mktemp("ci-examples"))


def check_in(checkout: Path, baseline: str, change=None) -> tuple[int, list[str]]:
    """`lensaudit check data/db --baseline BASELINE` in the checkout, with
    ``change`` (a function of slr-tokina.xml's lines) made first and undone after."""
    path = checkout / "data" / "db" / "slr-tokina.xml"
    original = path.read_bytes()
    if change is not None:
        lines = original.decode("utf-8").splitlines(keepends=True)
        path.write_text("".join(change(lines)), encoding="utf-8")
    try:
        command = [sys.executable, "-m", "lensaudit", "check", "data/db", "--baseline", baseline]
        result = subprocess.run(
            [*command, "--no-cache"], cwd=checkout, capture_output=True, text=True, timeout=600
        )
    finally:
        path.write_bytes(original)
    return result.returncode, result.stdout.splitlines()


def quoted_runs(command: str) -> list[list[str]]:
    """Each block of docs/ci.md that follows ``$ command``."""
    text = doc("docs/ci.md")
    starts = [m.end() for m in re.finditer(re.escape(f"$ {command}\n"), text)]
    return [block_after(text[start - len(command) - 3 :], command) for start in starts]


def assert_quoted_run(quoted: list[str], live: list[str]) -> None:
    """A quoted run is the live one, its known findings elided as "... (N known findings)"."""
    head = quoted.index("Known from baseline HEAD (not failing):")
    assert quoted[:head] == live[: live.index(quoted[head])]
    known = [line for line in live if line.startswith("  ")]
    position = 0
    for line in quoted[head + 1 :]:
        elided = re.fullmatch(r"  \.\.\. \((\d+) (?:more )?known findings\)", line)
        if elided:
            position += int(elided[1])
        elif line.startswith("  "):
            assert known[position] == line
            position += 1
    assert position == len(known)
    summary = next(line for line in quoted if line.startswith("lensaudit check FAILED"))
    assert summary == live[-1]


def test_ci_md_example_of_a_change_is_todays_output(lensfun_checkout):
    added = (
        '            <distortion model="poly3" focal="14.5" k1="-0.3"/>\n'
        '            <distortion model="ptlens" focal="15.5" a="0.01" b="nan" c="0"/>\n'
    )
    assert added in doc("docs/ci.md")
    status, live = check_in(
        lensfun_checkout, "HEAD", lambda lines: [*lines[:20], added, *lines[20:]]
    )
    quoted = quoted_runs("lensaudit check data/db --baseline HEAD")[0]
    assert_quoted_run(quoted, live)
    text = doc("docs/ci.md")
    after = text.index(quoted[-1]) + len(quoted[-1])
    assert text[after:].startswith(f"\n$ echo $?\n{status}\n")


def test_ci_md_example_of_a_broken_file_is_todays_output(lensfun_checkout):
    def broken(lines):
        assert lines[18].rstrip().endswith("/>")
        return [*lines[:18], lines[18].rstrip()[:-2] + "\n", *lines[19:]]

    status, live = check_in(lensfun_checkout, "HEAD", broken)
    assert status == 1
    assert_quoted_run(quoted_runs("lensaudit check data/db --baseline HEAD")[1], live)


def test_ci_md_counts_of_a_check_against_300_commits_before(lensfun_checkout):
    status, live = check_in(lensfun_checkout, "HEAD~300")
    assert status == 1
    new = [line for line in live if not line.startswith("  ")]
    codes = {}
    for line in new:
        found = re.search(r": (error|warning) \[([a-z-]+)\]", line)
        if found:
            codes[found.groups()] = codes.get(found.groups(), 0) + 1
    text = " ".join(doc("docs/ci.md").split())
    quoted = re.search(
        r"--baseline HEAD~300` at commit \w+ finds (\d+) new errors \(a second 500 mm entry "
        r"for the Canon RF 200-800mm, and (\d+) vignetting corrections that divide by zero "
        r"inside the image\) and (\d+) new warnings \((\d+) vignetting corrections below 0\.1, "
        r"(\d+) that brighten the image beyond its centre, and (\d+) lenses on a mount no file "
        r"defines\);.*? (\d+) findings are known and (\d+) is resolved",
        text,
    )
    assert quoted
    errors, zero, warnings, low, bright, mounts, known, resolved = map(int, quoted.groups())
    assert codes == {
        ("error", "duplicate-focal"): errors - zero,
        ("error", "vignetting-zero-in-image"): zero,
        ("warning", "vignetting-low-in-image"): low,
        ("warning", "vignetting-brightens"): bright,
        ("warning", "undefined-mount"): mounts,
    }
    assert low + bright + mounts == warnings
    assert live[-1].endswith(f"; {known} known from baseline HEAD~300, {resolved} resolved")


# --------------------------------------------------------- docs/vignetting.md


def brightening(database: Path | None) -> tuple[int, int, str, float]:
    """(entries, lenses, brightest lens, its C) of `scan --kind vignetting` brightening."""
    words = ["scan", "--no-cache", "--kind", "vignetting", "-f", "csv"]
    output = CliRunner().invoke(main, [*words, *([str(database)] if database else [])]).output
    rows = [r for r in csv.DictReader(io.StringIO(output)) if r["brightens"] == "true"]
    top = max(rows, key=lambda r: float(r["c_max"]))
    return len(rows), len({(r["maker"], r["lens"]) for r in rows}), top["lens"], float(top["c_max"])


def test_the_brightening_counts_of_docs_vignetting_md_are_todays(bundled_db, lensfun_head):
    text = doc("docs/vignetting.md")
    bundled, head = brightening(bundled_db), brightening(lensfun_head)
    row = re.search(r"\| C > 1\.05 inside the image[^|]*\| ([\d,]+) \| ([\d,]+) \|", text)
    assert row and (int(row[1].replace(",", "")), int(row[2].replace(",", ""))) == (
        bundled[0],
        head[0],
    )
    sentence = re.search(
        r"Brighter than the centre: (\d+) entries of (\d+) lenses in the bundled database,\s+"
        r"(\d+) entries of (\d+) lenses at the head\. The brightest is the Sony (.+?) at",
        text,
        re.DOTALL,
    )
    assert sentence
    assert tuple(map(int, sentence.groups()[:4])) == (*bundled[:2], *head[:2])
    assert " ".join(sentence[5].split()) == bundled[2] == head[2]
    assert f"{bundled[3]:.2f} times as bright" in " ".join(text.split())


# ------------------------------------------------- docs/projection.md, vignetting.md


def test_projection_md_says_where_the_plain_polynomial_puts_the_folded_point(bundled_db):
    from lensaudit.projection import lensfun_camera, project
    from lensaudit.read import read

    entries = read(bundled_db / "slr-tokina.xml").entries()
    camera = lensfun_camera(next(e for e in entries if e.line == 17), 6000, 4000)
    pixels, valid = project([3.732, 0.0, 1.0], camera, nan_for_invalid=False)
    x, y = (float(v) for v in pixels)
    low, high = 0.0, camera.max_angle_degrees  # the angle on that ray of the last pixel
    for _ in range(60):
        middle = (low + high) / 2
        at = float(project([math.tan(math.radians(middle)), 0.0, 1.0], camera)[0][0])
        low, high = (middle, high) if at < 5999.5 else (low, middle)
    edge = low
    text = " ".join(doc("docs/projection.md").split())
    quoted = re.search(
        r"75 degrees off axis, (\d+) degrees beyond the picture's right edge \(([\d.]+) "
        r"degrees on that ray\).*?at pixel \(([\d.]+), ([\d.]+)\), inside the image, (\d+) "
        r"pixels right of its centre",
        text,
    )
    assert quoted and not valid
    assert (quoted[3], quoted[4]) == (f"{x:.1f}", f"{y:.1f}")
    assert int(quoted[5]) == round(x - 2999.5) and 0 <= x < 6000
    assert quoted[2] == f"{edge:.1f}" and int(quoted[1]) == round(75 - edge)


def test_vignetting_md_names_the_lowest_correction_and_where_it_reaches_zero(bundled_db):
    output = CliRunner().invoke(main, ["scan", "--no-cache", "--kind", "vignetting", "-f", "csv"])
    rows = list(csv.DictReader(io.StringIO(output.output)))
    lowest = min(rows, key=lambda r: float(r["c_min"]) if r["c_min"] else math.inf)
    text = " ".join(doc("docs/vignetting.md").split())
    quoted = re.search(
        r"the (Canon EF 8-15mm f/4L Fisheye) at (\d+) mm, where C reaches (-?[\d.]+) at the "
        r"corner and crosses zero at r = ([\d.]+) \(f/([\d.]+)\)",
        text,
    )
    assert quoted
    assert quoted[1] in lowest["lens"] and float(lowest["focal"]) == float(quoted[2])
    assert f"{float(lowest['c_min']):.1f}" == quoted[3]
    assert f"{float(lowest['r_zero']):.2f}" == quoted[4]
    assert f"{float(lowest['aperture']):g}" == quoted[5]
