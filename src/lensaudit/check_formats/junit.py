"""JUnit XML, as CI systems display test results.

One ``<testsuite>`` per file; in it one ``<testcase>`` per finding, which
holds a ``<failure>`` when the finding fails the check, ``<skipped>`` when
it is known from the baseline, and passes (with the text in
``<system-out>``) for warnings and notices. A file without findings has one
passing test case, so that every file checked is listed. Paths are written
as the result holds them; ``lensaudit check`` makes them relative to the
root of the git repository that holds the database, as CI systems expect.
"""

from __future__ import annotations

import codecs
import re
import xml.etree.ElementTree as ET
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from ..check import CheckResult, Finding

# Characters XML 1.0 cannot hold at all.
_NOT_XML = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")

CLASSNAME = "lensaudit.check"


def _xml_text(text: str) -> str:
    return _NOT_XML.sub("\ufffd", text)


def _location(finding: Finding) -> str:
    return f"{finding.file}:{finding.line}" if finding.line else finding.file


def _testcase(finding: Finding) -> ET.Element:
    case = ET.Element(
        "testcase",
        classname=CLASSNAME,
        name=_xml_text(f"{_location(finding)} {finding.code}"),
        file=_xml_text(finding.file),
        line=str(finding.line),
    )
    text = _xml_text(f"{_location(finding)}: {finding.severity} [{finding.code}] {finding.message}")
    if finding.fails:
        failure = ET.SubElement(
            case, "failure", message=_xml_text(finding.message), type=finding.code
        )
        failure.text = text
    elif finding.known:
        ET.SubElement(case, "skipped", message=_xml_text(f"known from the baseline: {text}"))
    else:
        ET.SubElement(case, "system-out").text = text
    return case


def write(result: CheckResult, stream: TextIO) -> None:
    suites = ET.Element("testsuites", name="lensaudit check")
    totals = {"tests": 0, "failures": 0, "skipped": 0}
    by_file: dict[str, list[Finding]] = {f.file: [] for f in result.files}
    for finding in result.findings:
        by_file.setdefault(finding.file, []).append(finding)
    for file, findings in by_file.items():
        cases = [_testcase(f) for f in findings]
        if not cases:
            cases = [
                ET.Element(
                    "testcase",
                    classname=CLASSNAME,
                    name=_xml_text(f"{file} no findings"),
                    file=_xml_text(file),
                )
            ]
        counts = {
            "tests": len(cases),
            "failures": sum(f.fails for f in findings),
            "skipped": sum(f.known for f in findings),
        }
        suite = ET.SubElement(
            suites,
            "testsuite",
            name=_xml_text(file),
            errors="0",
            **{k: str(v) for k, v in counts.items()},
        )
        suite.extend(cases)
        for key, value in counts.items():
            totals[key] += value
    suites.attrib.update({k: str(v) for k, v in totals.items()}, errors="0")
    ET.indent(suites)
    document = ET.tostring(suites, encoding="unicode")
    if not _utf8(stream):  # a terminal's own encoding: ASCII, the rest as references
        document = document.encode("ascii", "xmlcharrefreplace").decode("ascii")
    stream.write('<?xml version="1.0" encoding="UTF-8"?>\n')
    stream.write(document)
    stream.write("\n")


def _utf8(stream: TextIO) -> bool:
    """Whether ``stream`` writes UTF-8 (a file written by lensaudit, a stream
    in memory), so that the document is UTF-8 as it says it is."""
    encoding = getattr(stream, "encoding", None)
    try:
        return encoding is None or codecs.lookup(encoding).name == "utf-8"
    except LookupError:
        return False
