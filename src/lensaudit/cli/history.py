"""``lensaudit history``: audit every revision of a Lensfun database kept in git."""

from __future__ import annotations

import io
import sys
from collections.abc import Callable
from pathlib import Path

import click

from ..commands import cycle_collector_off, refuse_unwritable, refuse_writing_inputs
from ..formats import printable
from ..history import Commit, HistoryError, Revision, audit_history, trend_figure
from ..history.commits import normalized_path
from ..history.index import caches, key_of
from ..read import parallel
from ..read.paths import display_path, enclosing_database
from ..writing import OutputSet
from .options import GivenPath, ProgressBar, cache_option, fail, not_blank


@click.command()
@click.argument("repository", metavar="[REPO]", required=False, type=GivenPath(path_type=Path))
@click.option(
    "--path",
    "db_path",
    default="data/db",
    show_default=True,
    callback=not_blank,
    help="Database directory (or XML file) inside REPO, relative to its root.",
)
@click.option(
    "--rev",
    "revision",
    default="HEAD",
    show_default=True,
    help="Revision whose history is audited.",
)
@click.option(
    "--since",
    metavar="DATE",
    default=None,
    help="Only commits from DATE on (YYYY-MM-DD[THH:MM], committer date).",
)
@click.option(
    "--until",
    metavar="DATE",
    default=None,
    help="Only commits up to DATE; a bare date includes the whole day.",
)
@click.option(
    "--first-parent",
    is_flag=True,
    help="Follow only the first parent of merges: a merged branch counts as its merge commit.",
)
@click.option(
    "-o",
    "--output",
    "output_dir",
    required=True,
    metavar="DIR",
    type=GivenPath(path_type=Path, file_okay=False),
    help="Directory for history.csv, introduced.csv, events.csv, trend.png and trend.svg.",
)
@cache_option
@click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors.")
def history(
    repository: Path | None,
    db_path: str,
    revision: str,
    since: str | None,
    until: str | None,
    first_parent: bool,
    output_dir: Path,
    cache: bool,
    quiet: bool,
) -> None:
    """Audit every revision of a Lensfun database kept in git.

    REPO is a git repository holding a Lensfun database; without REPO, the
    Lensfun checkout around the working directory (the database bundled with
    lensfunpy has no history). Reads the commits of REPO oldest to newest through git (nothing is
    checked out) and, for each commit that changes the database, counts the
    distortion entries per model, those with a finite r_max and those that
    fold inside their own image, in Hugin units and in the paper's units.

    \b
    Writes to DIR:
      history.csv     one row per commit that changes the database
      introduced.csv  each entry of the newest revision with a finite r_max,
                      and the commit that introduced its coefficients
      events.csv      along the first-parent line, each entry that starts
                      folding inside its image and each that stops, and where
      trend.png/.svg  entries, share with finite r_max and folds over time,
                      the paper's snapshot (2021-05-30) marked

    A progress bar is drawn when standard error is a terminal.
    """
    repository = repository if repository is not None else _checkout()
    refuse_writing_inputs([output_dir], [repository / db_path], repository / ".git")
    refuse_unwritable([output_dir / name for name in _WRITTEN], output_dir)
    try:
        output_dir.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        fail(f"cannot create {output_dir}: {error.strerror or error}")
    # --cache-dir has named the directory by now, as $LENSAUDIT_CACHE_DIR does.
    bar = ProgressBar("Auditing file versions", enabled=not quiet and sys.stderr.isatty())
    # What the history allocates (the summary of every file version) lives until
    # it ends. The trend figures are drawn by a process that imports matplotlib
    # meanwhile (forked now: the commits and the newest files are read beside it).
    with cycle_collector_off(), parallel.Beside(_drawn, _import_matplotlib) as trend:

        def revisions_read(newest: Commit, revisions: list[Revision]) -> None:
            # Drawn from here on, while the rest of the history is worked out.
            title = _title(repository, db_path, first_parent, newest)
            trend.send(([revision.record() for revision in revisions], title))

        try:
            result = audit_history(
                repository,
                db_path,
                revision=revision,
                since=since,
                until=until,
                first_parent=first_parent,
                cache=cache,
                progress=bar.update,
                revisions_read=revisions_read,
            )
        except HistoryError as error:
            bar.close()
            fail(str(error))
        bar.close()
        for warning in result.warnings:
            click.echo(f"lensaudit: warning: {printable(str(warning))}", err=True)

        written = _write_outputs(result, output_dir, cache, trend)
    if not quiet:
        _print_summary(result, written)


def _checkout() -> Path:
    """The Lensfun checkout around the working directory; exit 2 outside one."""
    found = enclosing_database()
    if found is None:
        fail(
            "no REPO, and the working directory is in no Lensfun checkout "
            "(the database bundled with lensfunpy has no history): give REPO"
        )
    return found.parents[1]


def _write_outputs(
    result, output_dir: Path, cache: bool | Path, trend: parallel.Beside
) -> list[Path]:
    """Write history.csv, introduced.csv, events.csv and the trend figures: all,
    or none. The figures are drawn by ``trend`` (see :func:`_figures`) while
    the other files are made."""
    contents: dict[str, str | bytes] = {}
    history_csv = io.StringIO()
    result.write_csv(history_csv)
    contents["history.csv"] = history_csv.getvalue()
    title = _title(result.repository, result.path, result.first_parent, result.newest)
    figures = _figures(result, title, contents["history.csv"], cache, trend)
    for name, write in (
        ("introduced.csv", result.write_introduced_csv),
        ("events.csv", result.write_events_csv),
    ):
        stream = io.StringIO()
        write(stream)
        contents[name] = stream.getvalue()
    contents |= figures()
    with OutputSet() as outputs:
        for name, data in contents.items():
            if isinstance(data, str):
                outputs.write_text(output_dir / name, data)
            else:
                outputs.write_bytes(output_dir / name, data)
    return [output_dir / name for name in contents]


def _title(repository: Path, db_path: str, first_parent: bool, newest: Commit) -> str:
    """The trend figure's title."""
    mode = "first-parent line" if first_parent else "all commits"
    path = display_path(normalized_path(db_path))
    name = display_path(repository.resolve().name)
    return f"{path} of {name} ({mode}) up to {newest.date[:10]}"


_FIGURES = ("trend.png", "trend.svg")
#: Every file written into DIR.
_WRITTEN = ("history.csv", "introduced.csv", "events.csv", *_FIGURES)


def _figures(
    result, title: str, history_csv: str, cache: bool | Path, trend: parallel.Beside
) -> Callable[[], dict[str, bytes]]:
    """What gives trend.png and trend.svg: as drawn last time for the same
    history.csv, title, matplotlib and lensaudit code (matplotlib is slow to
    import and to draw, and the history of an unchanged repository is the
    same), kept in the history's index (:mod:`lensaudit.history.index`), or
    drawn by ``trend``, which has been sent what to draw (``revisions_read``
    of :func:`~lensaudit.history.audit_history`) or is sent it now."""
    # importlib.metadata: slow to import, only for provenance
    from importlib.metadata import PackageNotFoundError, version

    index = caches(cache)[1]
    try:
        matplotlib_version = version("matplotlib")
    except PackageNotFoundError:
        matplotlib_version = ""
    key = key_of(matplotlib_version, title, history_csv)
    found = index.get("trend", key) if index is not None else None
    if (
        isinstance(found, tuple)
        and len(found) == len(_FIGURES)
        and all(isinstance(data, bytes) for data in found)
    ):
        trend.stop()
        return lambda: dict(zip(_FIGURES, found, strict=True))
    if not trend.sent:
        trend.send((result.records(), title))

    def drawn() -> dict[str, bytes]:
        figures = trend.result()
        if index is not None:
            index.put("trend", key, tuple(figures[name] for name in _FIGURES))
        return figures

    return drawn


def _import_matplotlib() -> None:
    """What drawing the trend figures needs, imported ahead (it is slow)."""
    import matplotlib.backends.backend_agg  # noqa: F401
    import matplotlib.backends.backend_svg  # noqa: F401
    import matplotlib.figure  # noqa: F401
    import numpy  # noqa: F401


def _drawn(request: tuple[list[dict], str]) -> dict[str, bytes]:
    """trend.png and trend.svg of (history.csv's rows, title): :func:`_draw`,
    looked up when called (it may be replaced)."""
    return _draw(*request)


def _draw(records: list[dict], title: str) -> dict[str, bytes]:
    """trend.png and trend.svg, one after the other. The figure is laid out
    once, as the PNG is drawn (each drawing would lay it out again, a third
    of its cost): the same PNG, and an SVG laid out with the PNG's measure
    of its text."""
    figure = trend_figure(records, title=title)
    dpi = figure.get_dpi()
    figure.set_dpi(_FORMATS["trend.png"]["dpi"])
    figure.get_layout_engine().execute(figure)
    figure.set_layout_engine("none")
    figure.set_dpi(dpi)

    def drawn(name: str) -> bytes:
        stream = io.BytesIO()
        figure.savefig(stream, **_FORMATS[name])
        return stream.getvalue()

    return {name: drawn(name) for name in _FORMATS}


_FORMATS = {
    "trend.png": {"format": "png", "dpi": 150},
    "trend.svg": {"format": "svg", "dpi": 150, "metadata": {"Date": None}},
}


def _print_summary(result, written: list[Path]) -> None:
    newest = result.newest
    last = next((r for r in reversed(result.revisions) if r.mainline), None)
    click.echo(
        f"{printable(f'{result.path} in {result.repository}')}: {result.commits:,} commits, "
        f"{len(result.revisions):,} change the database"
    )
    click.echo(
        f"{result.blobs:,} file versions: {result.blobs_read:,} read, "
        f"{result.blobs_reused:,} from the last run; {result.seconds:.1f} s"
    )
    if last is not None:
        counts = last.counts
        click.echo(
            f"newest {newest.short} {newest.date[:10]}: {counts['audited']:,} entries "
            f"audited, {counts['finite']:,} with finite r_max "
            f"({100 * last.share_finite:.1f}%); folding inside their own image: "
            f"{counts['folds_in_image']} ({counts['folds_in_image_rectilinear']} "
            f"rectilinear), in the paper's units "
            f"{counts['folds_in_image_paper_units_rectilinear']} rectilinear"
        )
    click.echo("wrote " + ", ".join(printable(str(p)) for p in written))
