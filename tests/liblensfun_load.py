"""What Lensfun master's liblensfun holds after loading one file, refused or not.

:func:`liblensfun_master.lenses` raises for a file liblensfun refuses; liblensfun
keeps, though, every lens it completed before the point where it stopped.
:func:`load_and_lenses` gives both: how the load went, and how many lenses it holds.
"""

from __future__ import annotations

import re

import liblensfun_master as master

#: liblensfun's warning: "file:line:column: message".
_WARNING = re.compile(r"^[^:\n]*:(\d+):(\d+): (.*)", re.DOTALL)


def load_and_lenses(data: bytes) -> tuple[master.LoadResult, int]:
    """How liblensfun's load of ``data`` went, and the number of lenses it holds
    after it (not decoded: a lens whose only model is a translation has a model
    string :func:`liblensfun_master.lenses` cannot read)."""
    with master._database(data, "test.xml") as (db, result):
        lib = master.library()
        return result, sum(1 for _ in master._null_terminated(lib.lf_db_get_lenses(db)))


def stop_line(result: master.LoadResult) -> int | None:
    """The line liblensfun names where it stopped (None where it loaded the file)."""
    if result.ok:
        return None
    found = _WARNING.match(result.warnings.splitlines()[-1] if result.warnings else "")
    if found is None:
        raise AssertionError(f"no position in liblensfun's warning {result.warnings!r}")
    return int(found.group(1))
