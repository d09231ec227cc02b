"""How the findings of one distortion entry are matched against a baseline's."""

from __future__ import annotations

from ...read.records import DistortionEntry
from ..matching import entry_content, lens_identity
from ..result import Finding, Identified


def entry_identified(finding: Finding, entry: DistortionEntry, file_name: str) -> Identified:
    """``finding`` about ``entry`` with its identities: its severity, code and
    the entry's own values with its lens by name; then without the name, for
    a renamed lens."""
    content = (finding.severity, finding.code, entry_content(entry))
    return Identified(
        finding, ((*content, lens_identity(entry.maker, entry.lens)), content), (file_name,)
    )
