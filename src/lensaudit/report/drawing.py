"""Figure 5 drawn in a process of its own while the rest of the report is made.

Importing matplotlib and drawing Figure 5 as PNG and SVG is half of a cold
report, and needs nothing but Figure 5's histogram. :meth:`Figure5Drawing.start`
forks a process that imports matplotlib at once, while this one reads and
audits the database and writes the other files; :meth:`~Figure5Drawing.draw`
sends it the histogram and :meth:`~Figure5Drawing.result` waits for the PNG
bytes and the SVG text it sends back. The process never touches a file: what
it draws is written here. It is forked only where that is safe and pays
(``os.fork`` exists, this process runs one thread, more than one CPU is
available); otherwise, and when it fails, the figure is drawn here, where any
error then shows itself. While it runs it holds a CPU
(:func:`lensaudit.read.parallel.hold`): on two CPUs, this process then reads
the database alone, rather than three processes sharing two CPUs.
"""

from __future__ import annotations

import io
import os
import pickle
from contextlib import contextmanager

from ..read import parallel

# typing only for type checkers
TYPE_CHECKING = False
if TYPE_CHECKING:
    from collections.abc import Iterator
    from typing import NoReturn

    from .histogram import Histogram

#: Bytes of the length that comes before the histogram sent to the process.
_LENGTH_BYTES = 8


def draw(histogram: Histogram) -> tuple[bytes, str]:
    """Figure 5 of ``histogram``: the PNG file's bytes and the SVG file's text."""
    from . import figures  # matplotlib: only where Figure 5 is drawn

    figure = figures.figure5(histogram)
    png = io.BytesIO()
    figures.save(figure, png, "png")
    return png.getvalue(), figures.svg_text(figure)


class Figure5Drawing:
    """Figure 5, drawn by a forked process (:meth:`start`) or here."""

    def __init__(self) -> None:
        self._pid: int | None = None
        self._requests: int | None = None  # write end: the histogram, to the process
        self._replies: int | None = None  # read end: what the process drew
        self._histogram: Histogram | None = None

    @classmethod
    def start(cls) -> Figure5Drawing:
        """A drawing whose process (where one is forked) imports matplotlib now."""
        drawing = cls()
        if parallel.can_fork():
            drawing._fork()
        return drawing

    def _fork(self) -> None:
        requests_read, requests_write = os.pipe()
        replies_read, replies_write = os.pipe()
        pid = os.fork()
        if pid == 0:
            os.close(requests_write)
            os.close(replies_read)
            _serve(requests_read, replies_write)
        os.close(requests_read)
        os.close(replies_write)
        self._pid, self._requests, self._replies = pid, requests_write, replies_read
        parallel.hold()  # the database is read beside it by this process alone (on two CPUs)

    def draw(self, histogram: Histogram) -> None:
        """Have Figure 5 of ``histogram`` drawn (see :meth:`result`)."""
        self._histogram = histogram
        descriptor, self._requests = self._requests, None
        if descriptor is None:
            return
        request = pickle.dumps(histogram)
        try:
            with open(descriptor, "wb", closefd=True) as stream:
                stream.write(len(request).to_bytes(_LENGTH_BYTES, "little") + request)
        except OSError:  # the process is gone: drawn here
            self.stop()

    def result(self) -> tuple[bytes, str]:
        """The PNG bytes and SVG text of the histogram given to :meth:`draw`."""
        if self._histogram is None:
            raise RuntimeError("Figure5Drawing.result() before draw()")
        drawn = None
        pid, replies = self._pid, self._replies
        if pid is not None and replies is not None:
            self._replies = None  # closed by _collect
            drawn = _collect(pid, replies)
            self._pid = None  # ended: _collect waited for it (else stop() ends it)
            parallel.release()
        return drawn if drawn is not None else draw(self._histogram)

    def stop(self) -> None:
        """End the process, if there is one still: its drawing is no longer wanted."""
        descriptors = [d for d in (self._requests, self._replies) if d is not None]
        self._requests = self._replies = None
        if self._pid is not None:
            parallel.stop(self._pid, *descriptors)
            self._pid = None
            parallel.release()
        else:
            for descriptor in descriptors:
                os.close(descriptor)


@contextmanager
def started() -> Iterator[Figure5Drawing]:
    """A :class:`Figure5Drawing` started now, whose process is ended with the block."""
    drawing = Figure5Drawing.start()
    try:
        yield drawing
    finally:
        drawing.stop()


def _collect(pid: int, replies: int) -> tuple[bytes, str] | None:
    """What the process ``pid`` sent through ``replies``, None if it failed;
    closes ``replies`` and waits for the process to end."""
    reply = parallel.received(pid, replies)
    if reply is None:
        return None
    try:
        png, svg = pickle.loads(reply)
    except (pickle.UnpicklingError, EOFError, ValueError, TypeError):
        return None
    return png, svg


def _serve(requests: int, replies: int) -> NoReturn:
    """The forked process: import matplotlib, draw the histogram sent, send back
    what it drew; leave without the parent's cleanup."""
    code = 1
    try:
        from . import figures  # noqa: F401  matplotlib, while the parent reads

        with open(requests, "rb", closefd=True) as stream:
            length = int.from_bytes(stream.read(_LENGTH_BYTES), "little")
            request = stream.read(length)
        if length and len(request) == length:
            reply = pickle.dumps(draw(pickle.loads(request)))
            with open(replies, "wb", closefd=True) as stream:
                stream.write(reply)
            code = 0
    finally:
        os._exit(code)
