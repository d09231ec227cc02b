"""Text: ``file:line[:column]: severity [code] message``, then a summary line.

Findings already in the baseline are listed after the new ones, under their
own heading, so that what a change introduces comes first.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TextIO

from . import printable, summary_line

if TYPE_CHECKING:
    from ..check import CheckResult, Finding


def finding_line(finding: Finding) -> str:
    """One finding as a compiler-style line."""
    where = printable(finding.file)
    if finding.line:
        where += f":{finding.line}"
        if finding.column:
            where += f":{finding.column}"
    return f"{where}: {finding.severity} [{finding.code}] {printable(finding.message)}"


def lines(result: CheckResult) -> list[str]:
    """The report as lines of text: the database checked first."""
    new = [f for f in result.findings if not f.known]
    known = [f for f in result.findings if f.known]
    out = [f"lensaudit check: {printable(result.database)}"]
    out += [finding_line(f) for f in new]
    if known:
        if out:
            out.append("")
        out.append(f"Known from baseline {printable(result.baseline or '')} (not failing):")
        out += ["  " + finding_line(f) for f in known]
    if out:
        out.append("")
    out.append(summary_line(result))
    return out


def write(result: CheckResult, stream: TextIO) -> None:
    stream.write("\n".join(lines(result)) + "\n")
