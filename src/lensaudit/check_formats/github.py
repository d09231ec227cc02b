"""GitHub Actions workflow commands: one annotation per new finding.

``::error file=F,line=L,col=C,title=T::message`` (``warning``, ``notice``
likewise) puts the finding on the pull request's line. Following GitHub's
rules, ``%``, CR and LF are escaped in the message, and also ``:`` and ``,``
in property values. Known findings are listed as plain log lines, which
GitHub does not annotate, with workflow commands stopped around them
(``::stop-commands::TOKEN`` ... ``::TOKEN::``): a lens name there is never
read as a command. A summary line ends the output.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TextIO

from ..read.cache import content_hasher
from . import printable, summary_line
from .text import finding_line

if TYPE_CHECKING:
    from ..check import CheckResult, Finding


def escape_data(text: str) -> str:
    """Escape a workflow command's message."""
    return text.replace("%", "%25").replace("\r", "%0D").replace("\n", "%0A")


def escape_property(text: str) -> str:
    """Escape a workflow command's property value."""
    return escape_data(text).replace(":", "%3A").replace(",", "%2C")


def annotation(finding: Finding) -> str:
    """The workflow command of one finding.

    Escaped first, so that CR and LF become ``%0D`` and ``%0A`` as GitHub
    expects; other control characters are then shown as ``\\xNN``.
    """
    properties = [f"file={printable(escape_property(finding.file))}"]
    if finding.line:
        properties.append(f"line={finding.line}")
        if finding.column:
            properties.append(f"col={finding.column}")
    properties.append(f"title={escape_property(f'lensaudit {finding.code}')}")
    message = printable(escape_data(finding.message))
    return f"::{finding.severity} {','.join(properties)}::{message}"


def write(result: CheckResult, stream: TextIO) -> None:
    out = [annotation(f) for f in result.findings if not f.known]
    known = [f for f in result.findings if f.known]
    if known:
        lines = [f"Known from baseline {printable(result.baseline or '')} (not failing):"]
        lines += ["  " + finding_line(f) for f in known]
        # Text from the database, where GitHub reads a command in a line starting
        # with "::" after spaces, or holding "##[": commands are stopped around it,
        # with a token no such text can hold (the digest of the text itself).
        token = content_hasher("\n".join(lines).encode("utf-8", "surrogatepass")).hexdigest()
        out += [f"::stop-commands::{token}", *lines, f"::{token}::"]
    out.append(summary_line(result))
    stream.write("\n".join(out) + "\n")
