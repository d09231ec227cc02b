"""The registry of ``lensaudit check``'s rules: one record per finding code.

Each module of this package is one family of codes, named after them. It
holds, for each code, a :class:`Rule`: the code, its severity, its scope,
a one-line summary, its documentation with a real failing and a real passing
example; and the family's ``find(context)``, which yields ``(index of the
file, Identified finding)`` for the files of a :class:`Context`. A module sets
``ACROSS_FILES = True`` when its rules need every file of the database at
once (a mount defined in another file), and ``ORDER``, where its findings
stand among others on the same line.

:func:`families` is what :mod:`lensaudit.check.findings` runs; ``--help``
and docs/ci.md's table of codes are made from :data:`RULES` (a test holds
the docs to it). Adding a rule: a module here (or a record and a few lines in
the module of its family), a test case in ``tests/rule_cases/``, and its line
in docs/ci.md.
"""

from __future__ import annotations

import importlib
import pkgutil
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from functools import cached_property
from types import ModuleType
from typing import Any

ERROR = "error"
WARNING = "warning"
NOTICE = "notice"
SEVERITIES = (ERROR, WARNING, NOTICE)

#: What a finding is about: one ``<distortion>``, ``<vignetting>`` or
#: ``<tca>`` element; a ``<lens>`` or ``<camera>``; a whole file; the
#: database's files together; the baseline a change is compared with.
SCOPES = ("entry", "lens", "file", "database", "baseline")


@dataclass(frozen=True)
class Rule:
    """One finding code.

    ``brief`` is what ``check --help`` says of it, ``summary`` what docs/ci.md's
    table says, ``doc`` why it matters and how it is decided. ``severity`` is
    the severity it is reported with; ``lesser``, when set, says when it is
    reported with ``lesser_severity`` instead ("when the two are identical").
    ``verbose`` rules are reported only with ``--verbose``. ``fails`` and
    ``passes`` are real examples: an element that gets the finding and a
    close one that does not.
    """

    code: str
    severity: str
    scope: str
    brief: str
    summary: str
    doc: str
    fails: str
    passes: str
    lesser: str = ""
    lesser_severity: str = ""
    verbose: bool = False

    def __post_init__(self) -> None:
        severities = {self.severity, self.lesser_severity or self.severity}
        if not severities <= set(SEVERITIES) or self.scope not in SCOPES:
            raise ValueError(f"rule {self.code}: severity {self.severity!r}, scope {self.scope!r}")
        if bool(self.lesser) != bool(self.lesser_severity):
            raise ValueError(f"rule {self.code}: lesser and lesser_severity go together")

    @property
    def severities(self) -> tuple[str, ...]:
        """Every severity it may be reported with."""
        return (self.severity, self.lesser_severity) if self.lesser else (self.severity,)


@dataclass
class Context:
    """What the rules look at: the files of a database (or a share of them),
    parsed, and the options of the check.

    ``solved`` holds, per file, the metrics of its distortion entries (None
    where r_max is infinite) and their r_corner; rules that look across files
    get none.
    """

    read: Sequence[Any]  # ParsedSource: imported lazily by the modules that need it
    margin: float
    verbose: bool
    known: Any = None  # lensaudit.check.known.Known, what a baseline holds
    solved: Sequence[tuple[list, list[float]]] | None = None

    @cached_property
    def entries(self) -> list[tuple[int, Any]]:
        """(index of its file, entry) of every distortion entry, in file order."""
        return [(index, entry) for index, file in enumerate(self.read) for entry in file.entries]

    @cached_property
    def metrics(self) -> list[Any]:
        """The metrics of each of :attr:`entries` (None where r_max is infinite)."""
        return [m for file_metrics, _ in self.solved or () for m in file_metrics]

    @cached_property
    def corners(self) -> list[float]:
        """The r_corner of each of :attr:`entries`."""
        return [c for _, file_corners in self.solved or () for c in file_corners]


def _modules() -> list[ModuleType]:
    """The family modules of this package, in the order of their ``ORDER``."""
    found = [
        importlib.import_module(f"{__name__}.{info.name}")
        for info in pkgutil.iter_modules(__path__)
        if not info.name.startswith("_")
    ]
    return sorted(found, key=lambda module: (module.ORDER, module.__name__))


_FAMILIES: list[ModuleType] = []


def families(across_files: bool | None = None) -> list[ModuleType]:
    """The family modules that find something on a database, in order: those
    that look at each file alone (``across_files=False``), those that need
    every file (True), or all of them (None)."""
    if not _FAMILIES:
        _FAMILIES.extend(_modules())
    return [
        module
        for module in _FAMILIES
        if getattr(module, "find", None) is not None
        and (across_files is None or getattr(module, "ACROSS_FILES", False) == across_files)
    ]


def rules() -> dict[str, Rule]:
    """Every rule, by code, in the order of the families."""
    if not _FAMILIES:
        _FAMILIES.extend(_modules())
    return {rule.code: rule for module in _FAMILIES for rule in module.RULES}


def run(families_run: Iterable[ModuleType], context: Context) -> list[tuple[int, Any]]:
    """(index of the file, Identified) of every finding of ``families_run`` on ``context``."""
    return [pair for module in families_run for pair in module.find(context)]


def severity_table() -> list[tuple[str, str, str]]:
    """(severity, code, summary) of every rule, in the order of docs/ci.md's
    table: the families' order, the rules made by the reader first."""
    return [(rule.severity, rule.code, rule.summary) for rule in rules().values()]


def codes_help(width: int = 79) -> str:
    """The codes of every rule for ``lensaudit check --help``, by severity,
    each with its :attr:`Rule.brief` (click's ``\\b`` keeps the layout)."""
    import textwrap

    groups = (
        ("Errors (fail the check):", ERROR, False),
        ("Warnings:", WARNING, False),
        ("Notices:", NOTICE, False),
        ("Notices with --verbose:", NOTICE, True),
    )
    blocks = []
    for title, severity, verbose in groups:
        chosen = [r for r in rules().values() if r.severity == severity and r.verbose == verbose]
        if not chosen:
            continue
        lines = ["\b", title]
        for rule in chosen:
            brief = rule.brief + (
                f" (a {rule.lesser_severity}: {rule.lesser})" if rule.lesser else ""
            )
            head = f"  {rule.code:<26} " if len(rule.code) <= 26 else f"  {rule.code}\n{'':29}"
            wrapped = textwrap.wrap(brief, width - 29)
            lines.append(head + wrapped[0])
            lines += [" " * 29 + more for more in wrapped[1:]]
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks) + "\n"


#: A link of docs/ci.md's table: [text](target.md#anchor) or [text](#anchor).
_LINK = re.compile(r"\[[^\]]*\]\(([\w.-]*\.md)?(#[\w-]*)?\)")


def _terminal_links(text: str) -> str:
    """``text`` with its Markdown links as the page they lead to (docs/ci.md for a
    section of its own)."""
    return _LINK.sub(lambda m: f"docs/{m.group(1) or 'ci.md'}", text)


def explain(code: str) -> str:
    """What a finding code means, as ``lensaudit check --explain CODE`` prints
    it: its severity and scope, when it is reported, why, and its real
    failing and passing examples. Raises KeyError for an unknown code."""
    import textwrap

    rule = rules()[code]
    lines = [f"{rule.code}: {rule.severity}, about one {rule.scope}"]
    if rule.lesser:
        lines.append(f"  (a {rule.lesser_severity} {rule.lesser})")
    if rule.verbose:
        lines.append("  (reported only with --verbose)")
    for title, text in (
        ("When", rule.summary),
        ("Why", rule.doc),
        ("Fails", rule.fails),
        ("Passes", rule.passes),
    ):
        wrapped = textwrap.wrap(
            _terminal_links(text), 76, initial_indent="  ", subsequent_indent="  ",
            break_on_hyphens=False, break_long_words=False,
        )  # fmt: skip
        lines += ["", f"{title}:", *wrapped]
    return "\n".join(lines) + "\n"


__all__ = [
    "ERROR",
    "NOTICE",
    "SCOPES",
    "SEVERITIES",
    "WARNING",
    "Context",
    "Rule",
    "codes_help",
    "explain",
    "families",
    "rules",
    "run",
    "severity_table",
]
