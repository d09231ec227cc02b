"""``lensaudit fix``: refit the models that fold inside or just outside their image, and
patch the XML."""

from __future__ import annotations

import json
import math
import shlex
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import click

from ..columns import FOLD_MARGIN
from ..formats import printable
from ..formats.csv_format import write_rows
from ..formats.table import text_table
from ..pipeline import run
from ..read import LoadError
from ..read.paths import in_bundled_database
from ..version import __version__
from ..writing import WriteError, check_replaceable
from ..xmlpatch import PatchError, unified_diff
from ..xmlpatch import write as write_patches
from .options import (
    ProgressBar,
    cache_option,
    database_paths,
    fail,
    format_option,
    output_file,
    output_stream,
    refuse_unwritable,
    refuse_writing_inputs,
)

if TYPE_CHECKING:
    from ..fix import FixResult
    from ..pipeline import Audit
    from ..xmlpatch import FilePatch


@click.command()
@database_paths
@click.option(
    "--lens",
    metavar="TEXT",
    default=None,
    help="Only lenses whose maker and name contain TEXT (case-insensitive).",
)
@click.option(
    "--focal", type=float, metavar="MM", default=None, help="Only entries calibrated at MM."
)
@click.option(
    "--target",
    type=float,
    metavar="R",
    default=None,
    help="Undistorted radius, Hugin units, up to which the fixed model must "
    "increase (r_max beyond it); inf: a model that never folds. "
    "[default: image radius times the margin, at least the image radius]",
)
@click.option(
    "--margin",
    type=float,
    metavar="M",
    default=FOLD_MARGIN,
    show_default=True,
    help="Fix entries with r_normalized < M; the fixed model reaches M times "
    "the image radius before it folds.",
)
@click.option(
    "--tolerance",
    type=float,
    metavar="PX",
    default=50.0,
    show_default=True,
    help="Largest change of D over the image, in pixels of a 6000x4000 frame "
    "(as liblensfun scales the model to it), "
    "for an entry to count as fixed.",
)
@format_option("table: results and the diff; csv: one row per entry; json: both as data.")
@output_file
@click.option(
    "--write",
    is_flag=True,
    help="Patch the XML files in place: only the fixed entries' coefficients change.",
)
@cache_option
def fix(
    paths: tuple[Path, ...],
    lens: str | None,
    focal: float | None,
    target: float | None,
    margin: float,
    tolerance: float,
    output_format: str,
    output: Path | None,
    write: bool,
    cache: bool,
) -> None:
    """Refit distortion models that fold inside their image, so that they do not.

    For every entry with r_normalized below the margin (by default 1.1, the
    margin below which `lensaudit check` warns: the entries that fold inside
    their image or just outside it), find the coefficients of the same model
    (ptlens a, b, c; poly3 k1; poly5 k1, k2) whose D(r) stays closest to the
    original over the image and that increase up to the target radius and
    reach margin x the image radius before folding, with a slope D' of at
    least 0.2 on the way (undistortion stretches the image by 1 / D'). An
    entry fixed passes `lensaudit check` with no fold finding. The image
    radius is scan's: the frame's corner hypot(aspect, 1), or a circular
    fisheye's image circle. The fit is a
    linear program (minimax over radii 0 to the image radius); the result is
    verified with the exact r_max solver, and the coefficients are rounded to
    the decimals the file uses (at least 5 significant digits).

    Changes of D are in pixels of a 6000x4000 frame as liblensfun applies the
    model to it, matching diagonals (Hugin r = 1 is 3606 px / hypot(aspect,
    1): 2000 px for a 3:2 calibration, 2163 px for 4:3): the largest change
    over radii 0 to the image radius, and the RMS over the image. An entry
    counts as fixed when the largest change is within --tolerance; the others
    are reported with the reason.

    PATH is a database directory (the files liblensfun reads there: every
    *.xml, also in subdirectories named *.xml), a Lensfun checkout
    (its data/db) or XML files. Without PATH: the database of the Lensfun
    checkout around the working directory, else the one bundled with
    lensfunpy. The
    database bundled with lensfunpy is never written. Without --write,
    the unified diff of what would change is printed. With --write, the files
    are patched in place: only the changed attribute values, every other byte
    as it was, each file replaced atomically; if any file changed since it
    was read, none is written.

    \b
    Exit status:
      0  done (whether or not every entry could be fixed)
      2  bad usage, or input that could not be read or patched
    """

    _check_options(target, margin, tolerance)
    refuse_writing_inputs([output], paths)
    refuse_unwritable([output])
    audit = _read_audit(paths, cache, write)
    if write:
        _refuse_unwritable_targets(audit, margin, lens, focal)
    results, patches = _refit(audit, margin, target, tolerance, lens, focal)
    written = _write_patches(patches) if write else []
    diff = "" if write else "".join(unified_diff(p) for p in patches)
    settings = {
        "margin": margin,
        "target": target,
        "tolerance_px": tolerance,
        "lens": lens,
        "focal": focal,
    }
    with output_stream(output) as stream:
        if output_format == "csv":
            _write_csv(results, stream)
        elif output_format == "json":
            _write_json(audit, results, settings, diff, written, stream)
        else:
            _write_table(audit, results, settings, patches, diff, written, stream)


def _read_audit(paths: tuple[Path, ...], cache: bool, write: bool) -> Audit:
    """The audit of the database at ``paths``; exits with status 2 where it cannot be had
    or (with ``write``) cannot be patched."""

    try:
        audit = run(list(paths) or None, cache=cache)
    except LoadError as error:
        fail(str(error))
    if audit.files and all(f.error for f in audit.files):
        fail("no file could be read: " + "; ".join(f"{f.name}: {f.error}" for f in audit.files))
    if write and audit.source.bundled:
        fail(
            "--write patches files in place: give the database PATH to patch "
            "(the database bundled with lensfunpy is not written)"
        )
    bundled = next((p for p in audit.source.paths if in_bundled_database(p)), None)
    if write and bundled is not None:
        fail(
            f"--write patches files in place: {bundled} is the database bundled with "
            "lensfunpy, which is not written; patch a copy of it instead"
        )
    return audit


def _refuse_unwritable_targets(
    audit: Audit, margin: float, lens: str | None, focal: float | None
) -> None:
    """Exit with status 2, before the refits, when a file that --write may
    patch (one holding an entry selected) cannot be replaced as
    :func:`lensaudit.writing.replace_files` replaces it."""
    from .. import fix as stage  # numpy: --help stays quick

    paths = {f.name: f.path for f in audit.files}
    names = {
        audit.entries[i].file for i in stage.select(audit, margin=margin, lens=lens, focal=focal)
    }
    try:
        check_replaceable(paths[name] for name in sorted(names) if name in paths)
    except WriteError as error:
        fail(str(error))


def _refit(
    audit: Audit,
    margin: float,
    target: float | None,
    tolerance: float,
    lens: str | None,
    focal: float | None,
) -> tuple[list[FixResult], list[FilePatch]]:
    """The results for the selected entries, and the patches of the files that change."""
    from .. import fix as stage  # numpy: --help stays quick

    audited = [i for i, entry in enumerate(audit.entries) if entry.status == "ok"]
    if (lens or focal is not None) and not stage.matching(audit, audited, lens=lens, focal=focal):
        wanted = [
            f"--lens {shlex.quote(lens)}" if lens else "",
            "" if focal is None else f"--focal {focal:g}",
        ]
        fail(
            f"no audited entry of {audit.source.label} matches {' and '.join(filter(None, wanted))}"
        )
    indices = stage.select(audit, margin=margin, lens=lens, focal=focal)
    # A few entries take a second; a file of thousands that fold, minutes.
    bar = ProgressBar("Refitting entries", enabled=sys.stderr.isatty())
    try:
        sources = stage.read_sources(audit, indices)
        results = stage.fix_audit(
            audit,
            indices,
            margin=margin,
            target=target,
            tolerance=tolerance,
            sources=sources,
            progress=bar.update,
        )
        patches = [p for p in stage.patches(results, sources) if p.changed]
    except PatchError as error:
        fail(str(error))
    finally:
        bar.close()
    return results, patches


def _write_patches(patches: list[FilePatch]) -> list[str]:
    """Patch the files in place, all or none (see :func:`lensaudit.xmlpatch.write`);
    the names of those written."""
    try:
        write_patches(patches)
    except (PatchError, WriteError) as error:
        fail(str(error))
    return [patch.name for patch in patches]


def _check_options(target: float | None, margin: float, tolerance: float) -> None:
    if target is not None and not target > 0:
        fail(f"--target {target:g}: expected a radius > 0 in Hugin units (or inf)")
    if not (margin > 0 and math.isfinite(margin)):
        fail(f"--margin {margin:g}: expected a finite number > 0 (1: the image radius)")
    if not tolerance >= 0:
        fail(f"--tolerance {tolerance:g}: expected pixels >= 0")


def _coefficients(names: tuple[str, ...], texts: tuple[str, ...]) -> str:
    return " ".join(f"{n}={t}" for n, t in zip(names, texts, strict=True)) if texts else "-"


def _number(value: float, digits: int = 4) -> str:
    if math.isnan(value):
        return "-"
    if math.isinf(value):
        return "inf" if value > 0 else "-inf"
    return f"{value:.{digits}g}"


def _ratio(value: float) -> str:
    return _number(value) if not math.isfinite(value) else f"{value:.3f}"


#: Columns of the table; each result takes two rows, its old and its new coefficients.
_TABLE_COLUMNS = (
    "where", "lens", "focal", "model", "coefficients",
    "r_max", "r_norm", "max px", "rms px", "min D'", "status",
)  # fmt: skip
_TABLE_RIGHT = [False, False, True, False, False, True, True, True, True, True, False]


def _write_table(
    audit: Audit,
    results: list[FixResult],
    settings: dict[str, Any],
    patches: list[FilePatch],
    diff: str,
    written: list[str],
    stream: TextIO,
) -> None:
    from ..fix import FRAME, SLOPE_FLOOR  # numpy: --help stays quick

    lines = _table_heading(audit, results, settings)
    if not results:
        stream.write("\n".join(map(printable, lines)) + "\n")
        return
    lines.append(
        f"Changes of D in pixels of a {FRAME} frame as liblensfun applies the model to it "
        "(diagonals matched: Hugin r 1 = 3606 px / hypot(aspect, 1), 2000 px at 3:2); "
        "maximum over radii 0 to the image radius, RMS over the image."
    )
    lines.append(
        f"min D': the smallest slope of the new D(r) up to where D reaches "
        f"{settings['margin']:g} x the image radius (kept at least {SLOPE_FLOOR:g}: "
        "undistortion stretches the image by 1 / D')."
    )
    lines.append("")
    rows = [[printable(cell) for cell in row] for row in _table_rows(results)]
    lines += text_table(_TABLE_COLUMNS, rows, right=_TABLE_RIGHT)
    lines += _table_ending(results, settings, patches, written)
    # Names from the database and file names must not move the terminal's cursor.
    stream.write("\n".join(map(printable, lines)) + "\n")
    if diff:
        stream.write("\n" + "\n".join(printable(line, tabs=True) for line in diff.split("\n")))


def _table_heading(audit: Audit, results: list[FixResult], settings: dict[str, Any]) -> list[str]:
    """The first lines: what was examined and how many entries were chosen."""

    margin = settings["margin"]
    lines = [f"lensaudit {__version__} fix: {audit.source.label}"]
    chosen = " matching the filters" if settings["lens"] or settings["focal"] else ""
    lines.append(
        f"{len(results)} entr{'y' if len(results) == 1 else 'ies'}{chosen} with "
        f"r_normalized < {margin:g} (D(r_max) below {margin:g} x the image radius)"
    )
    return lines


def _table_rows(results: list[FixResult]) -> list[list[str]]:
    """Two rows per result: the old coefficients, then the new ones and the outcome."""
    return [
        row
        for r in results
        for row in (
            [
                r.where,
                r.entry.lens,
                f"{r.entry.focal:g}",
                r.entry.model,
                "old " + _coefficients(r.names, r.old_texts),
                _number(r.r_max_before),
                _ratio(r.r_normalized_before),
                "",
                "",
                "",
                "",
            ],
            [
                "",
                "",
                "",
                "",
                "new " + _coefficients(r.names, r.new_texts),
                _number(r.r_max_after),
                _ratio(r.r_normalized_after),
                f"{r.max_change_px:.1f}" if r.new else "-",
                f"{r.rms_change_px:.1f}" if r.new else "-",
                _number(r.min_slope_after, 3) if r.new else "-",
                r.status,
            ],
        )
    ]


def _table_ending(
    results: list[FixResult],
    settings: dict[str, Any],
    patches: list[FilePatch],
    written: list[str],
) -> list[str]:
    """The last lines: why entries were not fixed, the counts, and what was written."""
    lines = []
    problems = [r for r in results if not r.fixed]
    if problems:
        lines.append("")
        lines += [f"{r.where}: {r.status}: {r.message}" for r in problems]
    together = [r for r in results if r.fixed and r.message]
    lines += [""] * bool(together) + [f"{r.where}: {r.message}" for r in together]
    zooms = [r for r in results if r.fixed and not math.isnan(r.r_normalized_between_after)]
    if zooms:
        lines.append("")
        lines.append(
            "Zooms, as liblensfun interpolates between calibrated focal lengths (every 0.01 mm):"
        )
        lines += [
            f"  {r.where}: smallest r_normalized {r.r_normalized_between_before:.3f} before, "
            f"{r.r_normalized_between_after:.3f} after (at {r.focal_between_after:g} mm)"
            for r in zooms
        ]
    fixed = len(results) - len(problems)
    lines.append("")
    lines.append(
        f"{fixed} fixed, {len(problems)} not fixed (tolerance {settings['tolerance_px']:g} px)."
    )
    if written:
        lines.append(f"Written: {', '.join(written)}.")
    elif patches:
        count = len(patches)
        lines.append(f"Nothing written; --write patches {count} file{'s' if count != 1 else ''}:")
    return lines


def _write_csv(results: list[FixResult], stream: TextIO) -> None:
    from ..fix import RECORD_COLUMNS  # numpy: --help stays quick

    records = [result.record() for result in results]
    write_rows(stream, RECORD_COLUMNS, ([r[name] for r in records] for name in RECORD_COLUMNS))


def _json_value(value: Any) -> Any:
    if isinstance(value, float):
        if math.isnan(value):
            return None
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
    return value


def _write_json(
    audit: Audit,
    results: list[FixResult],
    settings: dict[str, Any],
    diff: str,
    written: list[str],
    stream: TextIO,
) -> None:
    from ..fix import FRAME, RECORD_COLUMNS  # numpy: --help stays quick

    entries = []
    for result in results:
        record = result.record()
        for name in ("a", "b", "c", "k1", "k2"):
            text = record[f"{name}_new"]
            record[f"{name}_new"] = float(text) if text else None
        entries.append({name: _json_value(record[name]) for name in RECORD_COLUMNS})
    document = {
        "lensaudit": __version__,
        "database": {
            "label": audit.source.label,
            "paths": [str(p) for p in audit.source.paths],
        },
        "settings": {k: _json_value(v) for k, v in settings.items()},
        "units": {
            "radii": "Hugin units: 1 = half the short side of the image",
            "changes": f"pixels of a {FRAME} frame as liblensfun applies the model to it "
            "(diagonals matched: 3606 px / hypot(aspect, 1) per Hugin unit); "
            "max_change_half_diagonal: the largest as a fraction of the half diagonal",
            "min_slope_after": "smallest D' of the new model up to where D reaches the margin",
        },
        "entries": entries,
        "diff": diff,
        "written": written,
    }
    json.dump(document, stream, indent=1, allow_nan=False)
    stream.write("\n")
