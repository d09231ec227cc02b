"""Output formats of an audit: one module per format, each with ``write(audit, stream)``.

Formats that write a row per entry (:data:`ROW_FORMATS`) also render them
file by file: ``row_texts(columns)`` gives each row's text before and after
its metrics, ``metric_texts(metrics, statuses)`` that of its metrics,
``rows(leading, metrics, trailing)`` whole rows, and ``join(texts)`` the rows
of several files as one text (see :meth:`lensaudit.pipeline.Audit.rows`).
"""

from __future__ import annotations

from collections.abc import Callable
from importlib import import_module
from types import ModuleType
from typing import TYPE_CHECKING, TextIO

if TYPE_CHECKING:
    from ..pipeline import Audit

#: Format name -> module under lensaudit.formats.
FORMATS = {"table": "table", "csv": "csv_format", "json": "json_format"}
#: Formats whose rows are rendered per file, ahead of time, and cached.
ROW_FORMATS = ("csv", "json")


def writer(name: str) -> Callable[[Audit, TextIO], None]:
    """The ``write(audit, stream)`` function of the named format."""
    return import_module(f"{__name__}.{FORMATS[name]}").write


def row_format(name: str) -> ModuleType:
    """The module of a format in :data:`ROW_FORMATS`."""
    if name not in ROW_FORMATS:
        raise ValueError(f"{name!r} is not one of {', '.join(ROW_FORMATS)}")
    return import_module(f"{__name__}.{FORMATS[name]}")
