"""Output formats of an audit: one module per format, each with ``write(audit, stream)``."""

from __future__ import annotations

from collections.abc import Callable
from importlib import import_module
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from ..pipeline import Audit

#: Format name -> module under lensaudit.formats.
FORMATS = {"table": "table", "csv": "csv_format", "json": "json_format"}


def writer(name: str) -> Callable[[Audit, TextIO], None]:
    """The ``write(audit, stream)`` function of the named format."""
    return import_module(f"{__name__}.{FORMATS[name]}").write
