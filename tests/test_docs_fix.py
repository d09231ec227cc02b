"""What README.md and docs/fix.md quote of `lensaudit fix` is what it prints
today on the bundled database: the output block word for word, and every
change in pixels the prose names."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from lensaudit.cli import main

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def live(bundled_db) -> str:
    result = CliRunner().invoke(main, ["fix", "--no-cache"])
    assert result.exit_code == 0, result.output
    return re.sub(r"\(/\S*lensfunpy/db_files\)", "(.../lensfunpy/db_files)", result.output)


def quoted_block() -> str:
    text = (ROOT / "docs" / "fix.md").read_text()
    start = text.index("```\n$ lensaudit fix\n") + len("```\n$ lensaudit fix\n")
    return text[start : text.index("\n...\n```", start)]


def changes_in_px(live: str) -> dict[str, str]:
    """The `max px` of each entry of the live table, by lens."""
    found = {}
    lines = live.splitlines()
    for first, second in zip(lines, lines[1:], strict=False):
        if re.match(r"\S+\.xml:\d+ ", first) and second.lstrip().startswith("new "):
            lens = re.split(r"\s{2,}", first)[1]
            found[lens] = re.split(r"\s{2,}", second.strip())[-4]
    return found


def test_the_output_quoted_in_docs_fix_md_is_todays(live):
    block = quoted_block()
    assert live.startswith(block)


def test_every_change_the_docs_name_is_in_todays_table(live):
    changes = changes_in_px(live)
    assert len(changes) >= 6
    prose = (ROOT / "docs" / "fix.md").read_text().split("```")[2]
    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("## Fixing the folds") : readme.index("## Vignetting")]
    # Every "N px" but the tolerance ("within 50 px").
    named = re.findall(r"(?<!within )\b(\d+(?:\.\d)?) px", prose.split("## What")[0] + section)
    assert named
    values = {float(v) for v in changes.values()}
    for number in named:
        # "19.1 px" as in the table, "190 px" rounded from it
        assert any(abs(float(number) - v) <= (0.05 if "." in number else 0.5) for v in values), (
            number
        )


def test_the_options_and_columns_docs_fix_md_lists_are_the_commands():
    from lensaudit.cli.fix import fix as command
    from lensaudit.fix import RECORD_COLUMNS

    text = (ROOT / "docs" / "fix.md").read_text()
    table = text.split("## Options")[1].split("\n\n")[1]
    options = {param.opts[0]: param for param in command.params if param.opts[0].startswith("-")}
    for option, default in re.findall(
        r"^\| `(--[\w-]+)[^|]*\|.*\(default (\S+?)\) \|$", table, re.M
    ):
        assert float(options[option].default) == float(default), option
    listed = {name for name in re.findall(r"`(--[\w-]+)", table)}
    assert {name for name in options if name.startswith("--")} - {"--help"} <= listed | {
        "--no-cache"
    }
    columns = text.split("CSV and JSON columns:")[1].split("\n\n")[0]
    named = re.findall(r"`(\w+)`", columns)
    expanded = [
        n for n in named if n not in ("fixed", "beyond_tolerance", "no_solution", "not_located")
    ]
    old, new = (
        [f"{c}_old" for c in "a b c k1 k2".split()],
        [f"{c}_new" for c in "a b c k1 k2".split()],
    )
    at = expanded.index("a_old")
    expanded[at : at + 4] = [*old, *new]  # "a_old ... k2_old, ... a_new ... k2_new"
    assert expanded == list(RECORD_COLUMNS)
