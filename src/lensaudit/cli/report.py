"""``lensaudit report``: tables, figures and a self-contained HTML page in a directory."""

from __future__ import annotations

from pathlib import Path

import click

from ..commands import cycle_collector_off
from ..formats import printable
from ..read import LoadError
from ..report import ReportExistsError, audit, drawing, write_report
from ..report.writer import check_directory, planned_files
from .options import (
    GivenPath,
    cache_option,
    database_paths,
    fail,
    refuse_unwritable,
    refuse_writing_inputs,
)


@click.command()
@database_paths
@click.option(
    "-o",
    "--output",
    "output_dir",
    required=True,
    metavar="DIR",
    type=GivenPath(path_type=Path),
    help="Directory to write the report into (created if needed).",
)
@click.option("--force", is_flag=True, help="Replace report files already in DIR.")
@cache_option
@click.option(
    "--paper",
    is_flag=True,
    help="Also put the paper's printed Tables 1-2 and values beside this audit, "
    "each difference explained (paper_comparison.md, and in report.html).",
)
def report(
    paths: tuple[Path, ...], output_dir: Path, force: bool, cache: bool, paper: bool
) -> None:
    """Write tables, figures and a self-contained HTML report into DIR.

    PATH is a database directory (the files liblensfun reads there: every
    *.xml, also in subdirectories named *.xml), a Lensfun checkout
    (its data/db) or XML files. Without PATH: the database of the Lensfun
    checkout around the working directory, else the one bundled with
    lensfunpy.

    \b
    DIR receives:
      entries.csv            every entry with its metrics (as `scan -f csv`)
      vignetting.csv         every vignetting entry (as `scan --kind vignetting -f csv`)
      tca.csv                every TCA entry (as `scan --kind tca -f csv`)
      summary.json           counts, provenance, the folding entries
      table1.md, table1.csv  the paper's Table 1: finite / infinite r_max per model
      table2.md, table2.csv  the paper's Table 2: tail sign of the finite ones
      folding.csv            entries whose fold lies inside their own image
      fig5_r_normalized.*    the paper's Figure 5 (png, svg, and its counts as csv)
      report.html            one self-contained page: all of the above, browsable
      paper_comparison.md    with --paper only

    Existing report files in DIR are replaced only with --force.
    """
    # The directory, and each file it receives: an input may be in the directory.
    outputs = [output_dir, *(output_dir / name for name in planned_files(paper))]
    refuse_writing_inputs(outputs, paths)
    refuse_unwritable(outputs[1:], output_dir)
    try:  # report files in DIR without --force: refused before the work, not after
        check_directory(output_dir, planned_files(paper), force)
    except ReportExistsError as error:
        fail(str(error))
    values = None
    if paper:
        # numpy: `report --help` imports no heavy module (tests/test_imports.py)
        from ..report.paper import PaperValuesError, load_values

        try:
            values = load_values()
        except PaperValuesError as error:
            fail(str(error))
    # Figure 5's process (where one is forked) imports matplotlib while this one reads.
    with cycle_collector_off(), drawing.Figure5Drawing() as figure5:
        try:
            # Read once, with the calibrations: every table and figure comes from this read.
            audits = audit(list(paths) or None, cache=cache)
        except LoadError as error:
            fail(str(error))
        files = audits.distortion.files
        if files and all(f.error for f in files):
            fail("no file could be read: " + "; ".join(f"{f.name}: {f.error}" for f in files))
        try:
            written = write_report(
                audits, output_dir, force=force, paper_values=values, drawing=figure5
            )
        except ReportExistsError as error:
            fail(str(error))
        except OSError as error:
            fail(f"cannot write the report into {output_dir}: {error.strerror or error}")
    summary = audits.distortion.summary
    click.echo(f"lensaudit report: {printable(audits.distortion.source.label)}")
    click.echo(
        f"{summary.entries} entries audited, {summary.total.finite} with a finite "
        f"r_max, {len(summary.folding)} folding inside their image."
    )
    click.echo(
        printable(
            f"Wrote {len(written)} files into {output_dir}; open "
            f"{output_dir / 'report.html'} in a browser."
        )
    )
