"""Stage 6, outputs: ``history.csv`` and ``introduced.csv`` as text, and the
trend figure."""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime, timezone
from typing import TYPE_CHECKING, Any, TextIO

from ..formats.csv_format import write_rows

if TYPE_CHECKING:
    import pandas
    from matplotlib.figure import Figure

#: The day the paper's snapshot of the Lensfun database was taken.
PAPER_SNAPSHOT = "2021-05-30"


def write_csv(stream: TextIO, columns: Sequence[str], records: list[dict[str, Any]]) -> None:
    """Write ``records`` under a header of ``columns``, through lensaudit's one
    CSV writer (:func:`lensaudit.formats.csv_format.write_rows`): floats
    round-trip (``inf``; NaN empty), booleans as ``true``/``false``."""
    write_rows(stream, columns, [[record[name] for record in records] for name in columns])


def _utc(value: object) -> datetime:
    """A date as history.csv or a DataFrame of it holds one (text in ISO 8601,
    or a timestamp), as a naive UTC datetime (a date without a zone is UTC)."""
    if isinstance(value, str):
        value = datetime.fromisoformat(value)
    to_datetime = getattr(value, "to_pydatetime", None)  # a pandas Timestamp
    if to_datetime is not None:
        value = to_datetime()
    if not isinstance(value, datetime):
        raise TypeError(f"not a date: {value!r}")
    if value.tzinfo is not None:
        value = value.astimezone(timezone.utc).replace(tzinfo=None)
    return value


def trend_figure(
    history: pandas.DataFrame | Sequence[dict[str, Any]], title: str | None = None
) -> Figure:
    """The database over time: entries, share with finite r_max, folds.

    ``history`` is :meth:`History.records` or :meth:`History.to_dataframe`
    (or ``history.csv`` read with pandas). Only first-parent ("mainline")
    commits are drawn, so that a branch merged later does not zigzag the
    curves, in date order. The top panel shows entries audited and the share
    of them with a finite r_max; the bottom one counts entries folding
    inside their own image, in Hugin units and in the paper's mixed units
    (rectilinear lenses, as in the paper). The paper's snapshot date is
    marked on both.
    """
    import numpy as np  # numpy: only where arrays are needed, not on importing this module
    from matplotlib.figure import Figure  # matplotlib: only to draw

    records = history.to_dict("records") if hasattr(history, "to_dict") else list(history)
    rows = [r for r in records if str(r.get("mainline", True)).lower() in ("true", "1")]
    # By date: a rebased commit may keep a committer date older than its parent's.
    when = [_utc(r["date"]) for r in rows]
    order = sorted(range(len(rows)), key=when.__getitem__)
    rows = [rows[i] for i in order]
    dates = np.array([when[i] for i in order], dtype="datetime64[ns]")

    def column(name: str) -> list[float]:
        return [float(r[name]) for r in rows]

    figure = Figure(figsize=(9, 6.5), layout="constrained")
    top, bottom = figure.subplots(2, 1, sharex=True)
    if title:
        figure.suptitle(title)

    top.step(dates, column("audited"), where="post", color="C0", label="entries audited")
    top.set_ylabel("entries audited")
    share = top.twinx()
    share.step(
        dates,
        [100 * share for share in column("share_finite")],
        where="post",
        color="C1",
        label="with finite r_max (%)",
    )
    share.set_ylabel("with finite r_max (%)")
    share.set_ylim(0, 100)
    handles = top.get_legend_handles_labels()[0] + share.get_legend_handles_labels()[0]
    top.legend(handles=handles, loc="upper left")

    for name, label, style in (
        ("folds_in_image", "inside own image (Hugin units), all types", "-"),
        ("folds_in_image_rectilinear", "inside own image (Hugin units), rectilinear", "--"),
        ("folds_in_image_paper_units_rectilinear", "paper's mixed units, rectilinear", ":"),
    ):
        bottom.step(dates, column(name), where="post", linestyle=style, label=label)
    bottom.set_ylabel("entries folding")
    highest = int(max(column("folds_in_image"), default=0))
    bottom.set_ylim(-0.3, 1.6 * highest + 1.5)  # room for the legend above the curves
    bottom.legend(loc="upper left")

    snapshot = np.datetime64(PAPER_SNAPSHOT)
    for axes in (top, bottom):
        axes.axvline(snapshot, color="0.35", linewidth=1, linestyle="-.")
        axes.grid(alpha=0.3)
    top.annotate(
        f"paper's snapshot {PAPER_SNAPSHOT}",
        (snapshot, 1),
        xycoords=("data", "axes fraction"),
        xytext=(-4, -4),
        textcoords="offset points",
        ha="right",
        va="top",
        fontsize=8,
        color="0.35",
    )
    if len(dates) == 0:
        bottom.text(0.5, 0.5, "no revision", transform=bottom.transAxes, ha="center")
    return figure
