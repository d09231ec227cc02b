#!/usr/bin/env python
"""Reproduce the paper's Tables 1-2 and Figure 5, and put them beside its printed values.

    python scripts/reproduce_paper.py                    # lensfunpy's bundled database
    python scripts/reproduce_paper.py path/to/db         # any Lensfun database
    python scripts/reproduce_paper.py --git REPO --date 2021-05-30   # a revision from git
    python scripts/reproduce_paper.py ... -o DIR         # also write the full report

The paper's values are in data/paper_tables.json (installed with the package).
With --git, the newest
commit of REPO (a clone of the Lensfun database history) at or before the end
of DATE is extracted with `git archive` into a temporary directory; its
data/db is audited. Every difference from the paper is printed on one line
with its cause: database version, omitted coefficients, arithmetic or units.
Exit status: 0 done, 2 bad input.
"""

from __future__ import annotations

import argparse
import io
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from lensaudit import read  # noqa: E402
from lensaudit.read import LoadError  # noqa: E402
from lensaudit.report import (  # noqa: E402
    ReportAudits,
    ReportExistsError,
    audit,
    paper,
    write_report,
)
from lensaudit.report.histogram import figure5  # noqa: E402

#: Where the Lensfun repository keeps its database.
DB_DIR = "data/db"


def git_revision(repo: Path, date: str) -> tuple[str, str]:
    """(commit, "commit date subject") of the newest commit at or before the end of ``date``."""
    result = subprocess.run(
        [
            "git",
            "-C",
            str(repo),
            "log",
            f"--until={date}T23:59:59",
            "-1",
            "--format=%H%x00%ad %s",
            "--date=short",
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    if result.returncode != 0 or not result.stdout.strip():
        raise ValueError(
            f"no commit of {repo} at or before {date}: {result.stderr.strip() or 'empty history'}"
        )
    commit, _, description = result.stdout.strip().partition("\0")
    return commit, description


def extract(repo: Path, commit: str, target: Path) -> Path:
    """Write ``data/db`` of ``commit`` under ``target``; return the database directory."""
    archive = subprocess.run(
        ["git", "-C", str(repo), "archive", "--format=tar", commit, DB_DIR],
        capture_output=True,
        check=False,
    )
    if archive.returncode != 0:
        raise ValueError(
            f"git archive {commit} {DB_DIR} failed: "
            f"{archive.stderr.decode(errors='replace').strip()}"
        )
    with tarfile.open(fileobj=io.BytesIO(archive.stdout)) as tar:
        if hasattr(tarfile, "data_filter"):
            tar.extractall(target, filter="data")
        else:  # Python before 3.10.12 / 3.11.4: the archive comes from git, not a stranger
            tar.extractall(target)  # noqa: S202
    return target / DB_DIR


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "paths",
        nargs="*",
        type=Path,
        help="database directories or XML files (default: lensfunpy's)",
    )
    parser.add_argument(
        "--git", type=Path, metavar="REPO", help="a git clone of the Lensfun database history"
    )
    parser.add_argument(
        "--date",
        default="2021-05-30",
        help="with --git: use the newest revision up to this day "
        "(default: %(default)s, the paper's snapshot)",
    )
    parser.add_argument(
        "-o",
        "--output",
        type=Path,
        metavar="DIR",
        help="also write the report (tables, Figure 5, report.html) into DIR",
    )
    parser.add_argument("--force", action="store_true", help="replace files in DIR")
    args = parser.parse_args(argv)
    if args.git and args.paths:
        parser.error("give database PATHs or --git, not both")

    try:
        values = paper.load_values()
        with tempfile.TemporaryDirectory(prefix="lensaudit-paper-") as temporary:
            if args.git:
                commit, description = git_revision(args.git, args.date)
                directory = extract(args.git, commit, Path(temporary))
                source = read.DatabaseSource(
                    (directory,), f"Lensfun git revision {commit[:12]} ({description})"
                )
                files = read.read_files(read.expand(source.paths), calibrations=True)
                audits = ReportAudits.of_database(read.Database(source, files))
            else:
                audits = audit(args.paths or None)
            omitted = paper.omitted_coefficients(audits.distortion, audits.files)
            comparison = paper.compare(audits.distortion, values, omitted)
            print("\n".join(paper.text_lines(comparison)))
            histogram = figure5(audits.distortion)
            print(
                f"\nFigure 5: {histogram.entries} rectilinear entries with finite r_max; "
                f"{histogram.below_one} below 1 in correct units, "
                f"{histogram.below_one_paper} in the paper's units."
            )
            if args.output:
                written = write_report(audits, args.output, force=args.force, paper_values=values)
                print(
                    f"Wrote {len(written)} files into {args.output} "
                    f"(fig5_r_normalized.png, paper_comparison.md, report.html, ...)"
                )
    except (LoadError, ValueError, paper.PaperValuesError, ReportExistsError, OSError) as error:
        print(f"reproduce_paper: error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
