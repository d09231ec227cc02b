"""lensaudit: find where polynomial lens-distortion models fold back.

A radial distortion D(r) = r F(r) is invertible only up to its first local
maximum, r_max. lensaudit computes r_max for every model of a Lensfun
database and compares it with the image corner.

>>> import lensaudit
>>> frame = lensaudit.audit()            # the database bundled with lensfunpy (*)
>>> frame[frame.folds_in_image]          # entries that fold inside the image

(*) Inside a Lensfun checkout, its ``data/db``, as for ``lensaudit scan``.

The submodules follow the pipeline (:mod:`~lensaudit.pipeline`):
:mod:`~lensaudit.read` (files to tables, the only code that reads XML),
:mod:`~lensaudit.normalizer` (models to cubic form), :mod:`~lensaudit.solver`
(r_max), :mod:`~lensaudit.metrics` and :mod:`~lensaudit.summary`, then
:mod:`~lensaudit.formats`.
"""

from __future__ import annotations

import os
import sys


def _interrupted_while_starting(signum: int, frame: object) -> None:
    """Ctrl-C while the ``lensaudit`` command imports what it needs: nothing
    is written yet, so it ends at once, as it ends any other time."""
    try:
        os.write(2, b"lensaudit: interrupted\n")
    except OSError:  # standard error closed: the status says it
        pass
    os._exit(130)


# The command (``python -m lensaudit``, while its module is located sys.argv[0]
# is "-m"; the console script ``lensaudit``) takes Ctrl-C from its first line
# on, before its imports: `lensaudit.console.run` then installs its own handler.
# `_signal` is the interpreter's own, already loaded: no import to interrupt.
if getattr(sys, "argv", None) and (
    sys.argv[0] == "-m"
    or os.path.splitext(os.path.basename(sys.argv[0]))[0].removesuffix("-script") == "lensaudit"
):
    import _signal

    _signal.signal(_signal.SIGINT, _interrupted_while_starting)

from collections.abc import Sequence  # noqa: E402 - after Ctrl-C is taken

from .version import __version__  # noqa: E402

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any

    import pandas

__all__ = ["__version__", "audit", "min_positive_root", "run"]


def audit(
    path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | None = None,
) -> pandas.DataFrame:
    """Audit a Lensfun database and return one row per distortion entry.

    ``path`` is a database directory, an XML file, a list of those, or None
    for the Lensfun checkout around the working directory, else the database
    bundled with lensfunpy (as ``lensaudit scan`` without a path). Columns are
    :data:`lensaudit.pipeline.COLUMNS`; r_max and d_max are in Hugin units
    (1 = half the short side of the calibration image).
    """
    from .pipeline import run  # every `import lensaudit.X` runs this file: keep X light

    return run(path).to_dataframe()


def __getattr__(name: str) -> Any:
    # Lazy, so that `import lensaudit` and `lensaudit --help` stay fast.
    if name == "run":
        from .pipeline import run  # the reader, the column names stay free of it (tests)

        return run
    if name == "min_positive_root":
        from .solver import min_positive_root  # numpy (solver.arrays); typing on a warm scan

        return min_positive_root
    raise AttributeError(f"module 'lensaudit' has no attribute {name!r}")
