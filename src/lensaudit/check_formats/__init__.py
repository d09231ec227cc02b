"""Output formats of ``lensaudit check``: one module per format, each with
``write(result, stream)`` taking a :class:`lensaudit.check.CheckResult`."""

from __future__ import annotations

from collections.abc import Callable
from importlib import import_module
from typing import TYPE_CHECKING, TextIO

from ..formats import printable

if TYPE_CHECKING:
    from ..check import CheckResult

#: Format name -> module under lensaudit.check_formats.
FORMATS = {"text": "text", "json": "json_format", "github": "github", "junit": "junit"}


def writer(name: str) -> Callable[[CheckResult, TextIO], None]:
    """The ``write(result, stream)`` function of the named format."""
    return import_module(f"{__name__}.{FORMATS[name]}").write


def summary_line(result: CheckResult) -> str:
    """One sentence: what was checked, what was found, whether the check fails."""
    counts = result.counts()
    parts = [_plural(counts["error"], "error"), _plural(counts["warning"], "warning")]
    if counts["notice"]:
        parts.append(_plural(counts["notice"], "notice"))
    found = ", ".join(parts)
    if result.baseline is not None:
        found += (
            f"; {counts['known']} known from baseline {printable(result.baseline)}, "
            f"{result.resolved} resolved"
        )
    verdict = "FAILED" if result.failed else "passed"
    return (
        f"lensaudit check {verdict}: {_plural(len(result.files), 'file')}, "
        f"{_plural(result.entries, 'distortion entry', 'distortion entries')}; {found}"
    )


def _plural(count: int, singular: str, plural: str | None = None) -> str:
    return f"{count} {singular if count == 1 else plural or singular + 's'}"
