"""What the vignetting and TCA families share: their audits run over the
records of the files that parsed, a batch at a time, and each record's
finding matched against a baseline by its content."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from types import ModuleType
from typing import Any

from ... import calibrations
from ...read.records import STATUS_OK
from ..matching import calibration_content, lens_identity
from ..result import Finding, Identified, clip, clip_key, entry_key
from . import ERROR, NOTICE, WARNING, Context
from .input_errors import RULES as INPUT_RULES
from .input_errors import STATUS_RULES

#: Vignetting or TCA records audited in one batch of arrays.
RECORDS_AT_ONCE = 16384

#: The rule of each status of a vignetting or TCA entry that could not be
#: audited (a file's own problems are its file's finding).
ENTRY_STATUS_RULES = {status: rule for status, rule in STATUS_RULES.items() if rule in INPUT_RULES}

#: (severity, code, text) of an audited record, or None.
Wording = Callable[[dict[str, Any]], "tuple[str, str, str] | None"]


def calibration_findings(
    context: Context, kind: str, audit_module: ModuleType, wording: Wording
) -> Iterable[tuple[int, Identified]]:
    """Findings of the audit of one kind (``audit_module``, :mod:`lensaudit.vignetting`
    or :mod:`lensaudit.tca`) in the files of ``context`` that parsed: each
    record that could not be audited, and what ``wording`` says of each one
    that was, if its severity is shown (notices only with ``--verbose``)."""
    shown = {ERROR, WARNING} | ({NOTICE} if context.verbose else set())
    read = context.read
    parsed = [(index, file) for index, file in enumerate(read) if file.problem is None]
    parts = [file.calibrations[kind] for _, file in parsed if kind in file.calibrations]
    records = calibrations.CalibrationRecords.joined(kind, parts)
    if not records:
        return
    owners = [index for index, file in parsed for _ in range(len(file.calibrations.get(kind, ())))]
    # Each record is audited alone: a part at a time, the audit's arrays stay small.
    for start in range(0, len(records), RECORDS_AT_ONCE):
        part = records.part(start, start + RECORDS_AT_ONCE)
        for position, item in _part_findings(kind, audit_module, wording, part, shown):
            index = owners[start + position]
            yield index, item._replace(names=(read[index].source.file_name,))


def findings_of(records: Iterable[dict[str, Any]], kind: str, wording: Wording) -> list[tuple]:
    """(severity, code, file, line, message) of each of ``records`` (dicts of
    an audit's ``records()``), by file and line: the input error of each that
    could not be audited (the rules of :mod:`.input_errors`; whole-file
    problems are their file's own finding), and for each audited one what
    ``wording`` says of it, (severity, code, text) or None, its text led by
    the entry's name."""
    found = []
    for record in records:
        status = record["status"]
        if status == STATUS_OK:
            said = wording(record)
            if said is not None:
                severity, code, text = said
                name = describe(record, kind)
                found.append((severity, code, record["file"], record["line"], f"{name}: {text}"))
        elif status in ENTRY_STATUS_RULES:
            rule = ENTRY_STATUS_RULES[status]
            text = f"{describe(record, kind)}: {record['message']}"
            found.append((rule.severity, rule.code, record["file"], record["line"], text))
    found.sort(key=lambda f: (f[2], f[3]))
    return found


def describe(record: dict[str, Any], element: str) -> str:
    """Short name of a vignetting or TCA entry: its lens and calibration point,
    as far as known."""
    name = " ".join(part for part in (record.get("maker"), record.get("lens")) if part)
    lens = record.get("lens") or ""
    maker = record.get("maker") or ""
    if maker and lens.lower().startswith(maker.lower()):
        name = lens
    details = []
    for key, unit in (("focal", " mm"), ("aperture", ""), ("distance", " m")):
        value = record.get(key)
        if isinstance(value, float) and value == value:
            details.append(f"f/{value:g}" if key == "aperture" else f"{value:g}{unit}")
    where = f"<{element}>" + (f" at {', '.join(details)}" if details else "")
    return f"{name or 'unnamed lens'} {where}"


def _part_findings(
    kind: str,
    audit_module: ModuleType,
    wording: Wording,
    records: calibrations.CalibrationRecords,
    shown: set[str],
) -> Iterable[tuple[int, Identified]]:
    """(position in ``records``, finding) of each of the audit's findings
    whose severity is ``shown``; its file names come later."""
    import numpy as np  # numpy: only where arrays are needed, not on importing this module

    with np.errstate(all="ignore"):
        audit = audit_module.audit_entries(records)
    severities = audit.metrics["severity"].tolist()
    # Entry objects only for the records with a finding: a database has tens of thousands.
    for position, status in enumerate(records.column("status")):
        if status == STATUS_OK:
            if severities[position] not in shown:
                continue
        elif status not in ENTRY_STATUS_RULES:
            continue
        entry = records[position]
        record = _record(audit, position)
        for severity, code, _, _, message in findings_of([record], kind, wording):
            finding = Finding(
                severity,
                code,
                entry.file,
                entry.line,
                0,
                clip(message),
                clip_key(entry_key(entry)),  # the same fields as a distortion entry's
            )
            content = (severity, code, kind, calibration_content(entry))
            keys = ((*content, lens_identity(entry.maker, entry.lens)), content)
            yield position, Identified(finding, keys, ())


def _record(audit: calibrations.CalibrationAudit, position: int) -> dict:
    """One entry of a vignetting or TCA audit as the dict its ``records()`` gives."""
    entry = audit.entries[position]
    ok = entry.status == STATUS_OK
    record = {}
    for name in audit.COLUMNS:
        if name not in audit.METRIC_COLUMNS:
            record[name] = getattr(entry, name)
        elif name in audit.BOOL_COLUMNS:
            record[name] = bool(audit.metrics[name][position]) if ok else None
        else:
            value = audit.metrics[name][position]
            record[name] = value.item() if hasattr(value, "item") else value
    return record
