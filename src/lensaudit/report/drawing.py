"""Figure 5 drawn in a process of its own while the rest of the report is made.

Importing matplotlib and drawing Figure 5 as PNG and SVG is half of a cold
report, and needs nothing but Figure 5's histogram. :meth:`Figure5Drawing.start`
forks a process that imports matplotlib at once, while this one reads and
audits the database and writes the other files; :meth:`~Figure5Drawing.send`
sends it the histogram and :meth:`~Figure5Drawing.result` waits for the PNG
bytes and the SVG text it sends back (see :class:`lensaudit.read.parallel.Beside`).
The process never touches a file: what it draws is written here. It is
forked only where that is safe and pays (``os.fork`` exists, this process
runs one thread, more than one CPU is available); otherwise, and when it
fails, the figure is drawn here, where any error then shows itself. While
it runs it holds a CPU
(:func:`lensaudit.read.parallel.hold`): on two CPUs, this process then reads
the database alone, rather than three processes sharing two CPUs.
"""

from __future__ import annotations

import io

from ..read import parallel

# typing only for type checkers
TYPE_CHECKING = False
if TYPE_CHECKING:
    from .histogram import Histogram


def draw(histogram: Histogram) -> tuple[bytes, str]:
    """Figure 5 of ``histogram``: the PNG file's bytes and the SVG file's text."""
    from . import figures  # matplotlib: only where Figure 5 is drawn

    figure = figures.figure5(histogram)
    png = io.BytesIO()
    figures.save(figure, png, "png")
    return png.getvalue(), figures.svg_text(figure)


class Figure5Drawing(parallel.Beside):
    """Figure 5, drawn by a forked process (:meth:`start`) or here; the process
    holds a CPU while it runs. ``with Figure5Drawing() as drawing:`` starts it,
    and ends its process with the block."""

    def __init__(self) -> None:
        # draw() looked up when called: it may be replaced (tests).
        super().__init__(lambda histogram: draw(histogram), _import_figures, hold=True)


def _import_figures() -> None:
    from . import figures  # noqa: F401  matplotlib, while the parent reads
