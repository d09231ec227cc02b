"""The registry of check's rules: every code documented, in ``--help`` and in
docs/ci.md, reported with its own severity, and held by a failing and a
passing case (tests/rule_cases/, see its README)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from click.testing import CliRunner

from lensaudit.check import check
from lensaudit.check import rules as registry
from lensaudit.cli import main

ROOT = Path(__file__).resolve().parents[1]
CASES = Path(__file__).resolve().parent / "rule_cases"
RULES = registry.rules()
#: The codes of a file the reader could not read at all.
FILE_CODES = {"xml-error", "not-a-database", "unreadable"}
FAILS_MARK = "<!-- fails -->"
#: Codes no database can make, each with the test that makes it otherwise.
FAILING_ELSEWHERE = {
    # A defect of the solver: the test makes the solver raise for one entry.
    "r-max-not-computable": (
        "test_check.py",
        "test_entry_whose_r_max_cannot_be_computed_is_an_error_and_the_others_are_checked",
    ),
}


def test_every_rule_is_documented_with_a_real_failing_and_passing_example():
    for rule in RULES.values():
        for name in ("brief", "summary", "doc", "fails", "passes"):
            assert getattr(rule, name).strip(), f"{rule.code}: no {name}"
        assert rule.fails != rule.passes


def test_codes_are_unique_and_spelled_as_codes():
    codes = [rule.code for module in registry.families() for rule in module.RULES]
    codes += [rule.code for module in registry._FAMILIES for rule in module.RULES
              if module not in registry.families()]  # fmt: skip
    assert len(set(codes)) == len(RULES)
    assert all(re.fullmatch(r"[a-z0-9]+(-[a-z0-9]+)*", code) for code in RULES)


def test_docs_table_of_codes_is_the_registry():
    text = (ROOT / "docs" / "ci.md").read_text(encoding="utf-8")
    start = text.index("| severity | code | when |")
    rows = []
    for line in text[start:].splitlines()[2:]:
        if not line.startswith("|"):
            break
        severity, code, when = (cell.strip() for cell in line.strip("|").split(" | ", 2))
        rows.append((severity, code.strip("`"), when))
    assert rows == registry.severity_table()


def test_check_help_lists_every_code_with_its_severity():
    shown = CliRunner().invoke(main, ["check", "--help"], terminal_width=100).output
    heading = {"error": "Errors", "warning": "Warnings", "notice": "Notices"}
    sections = re.split(r"\n  (?=Errors|Warnings|Notices)", shown)
    for rule in RULES.values():
        (section,) = [s for s in sections if re.search(rf"^\s+{re.escape(rule.code)}\b", s, re.M)]
        assert section.startswith(heading[rule.severity]), rule.code
        assert ("--verbose" in section.splitlines()[0]) == rule.verbose, rule.code


def _cases() -> list[tuple[str, str]]:
    return [
        (code, kind)
        for code in RULES
        for kind in ("fails", "passes")
        if not (kind == "fails" and code in FAILING_ELSEWHERE)
    ]


def test_every_code_has_a_failing_and_a_passing_case():
    missing = [f"{code}/{kind}" for code, kind in _cases() if not (CASES / code / kind).is_dir()]
    assert not missing
    for code, (module, test) in FAILING_ELSEWHERE.items():
        assert not (CASES / code / "fails").exists(), f"{code}: a case now exists; use it"
        source = (Path(__file__).parent / module).read_text(encoding="utf-8")
        assert f"def {test}(" in source and f'"{code}"' in source, code
    unknown = {p.name for p in CASES.iterdir() if p.is_dir()} - set(RULES)
    assert not unknown


@pytest.mark.parametrize(("code", "kind"), _cases(), ids=[f"{c}-{k}" for c, k in _cases()])
def test_rule_case(code: str, kind: str):
    case = CASES / code / kind
    if not case.is_dir():
        pytest.fail(f"no test case {case.relative_to(CASES.parent)}")
    baseline = CASES / code / "baseline"
    result = check(case, baseline=baseline if baseline.is_dir() else None, verbose=True)
    found = {(Path(f.file).name, f.line) for f in result.findings if f.code == code}
    if kind == "passes":
        assert not found
        # A case that the reader cannot read passes every rule without testing one.
        assert not [f for f in result.findings if f.code in FILE_CODES], case
        return
    assert found == _expected(case)


def _expected(case: Path) -> set[tuple[str, int]]:
    """(file name, line) of each finding a failing case expects: its lines
    marked ``<!-- fails -->``, and the ``name:line`` lines of its expect.txt
    (a finding at line 0, about a whole file, or about a file that cannot be
    read)."""
    expected = set()
    listed = case / "expect.txt"
    if listed.is_file():
        for item in listed.read_text(encoding="utf-8").split():
            name, line = item.rsplit(":", 1)
            expected.add((name, int(line)))
    for path in case.glob("*.xml"):
        if not path.is_file():
            continue  # the unreadable file of a case, which expect.txt names
        text = path.read_text(encoding="utf-8", errors="replace")
        expected |= {
            (path.name, n) for n, line in enumerate(text.splitlines(), 1) if FAILS_MARK in line
        }
    assert expected, f"{case}: no line marked {FAILS_MARK} and no expect.txt"
    return expected


def test_every_finding_on_the_bundled_database_has_a_severity_of_its_rule(bundled_db):
    result = check(bundled_db, verbose=True)
    assert result.findings
    for finding in result.findings:
        assert finding.severity in RULES[finding.code].severities, finding


def test_the_code_names_the_library_exports_are_the_registrys():
    from lensaudit.check import result

    named = {
        name: value
        for name, value in vars(result).items()
        if name.isupper() and isinstance(value, str) and re.fullmatch(r"[a-z]+(-[a-z]+)+", value)
    }
    assert named and set(named.values()) <= set(RULES)


@pytest.mark.parametrize("code", list(RULES))
def test_check_explain_says_when_why_and_the_real_examples(code):
    rule = RULES[code]
    shown = CliRunner().invoke(main, ["check", "--explain", code])
    assert shown.exit_code == 0, shown.output
    flat = " ".join(shown.output.split())
    assert flat.startswith(f"{code}: {rule.severity}, about one {rule.scope}")
    for text in (rule.summary, rule.doc, rule.fails, rule.passes):
        # Each text word for word; a Markdown link is shown as the page it leads to.
        for part in re.split(r"\[[^\]]*\]\([^)]*\)", text):
            assert " ".join(part.split()) in flat


def test_check_explain_of_an_unknown_code_is_bad_usage_naming_the_codes():
    shown = CliRunner().invoke(main, ["check", "--explain", "fold-everywhere"])
    assert shown.exit_code == 2
    assert "'fold-everywhere' is no finding code" in shown.output
    assert all(code in shown.output for code in RULES)
