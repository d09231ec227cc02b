"""Work on every core: files parsed (the reader), a share of the files'
rules (check), Figure 5 drawn beside the report (:mod:`lensaudit.report.drawing`).

:func:`map_sized` applies a function to a list of items on every CPU.
Where it is safe and pays (``os.fork`` exists, this process runs one thread,
more than one CPU is available and there is enough to do), it forks a
process per CPU but one; this process and those take the items, largest
first, each the next one left when it is free, so that a process slowed by
another (the report's drawing, a busy machine) takes fewer. The items left
are handed out as tickets in a pipe, which every process reads a ticket at
a time. A forked process sends its results back through a pipe as
:mod:`marshal` data (so results must be plain data). An item whose process
fails is done here afterwards, where any error then shows itself.
:func:`shares` splits items into shares of about equal size, for work done
a share at a time. :class:`Beside` is work done by one process forked
ahead of it (a drawing: it imports matplotlib at once and waits for what
to draw), with the same rules.
"""

from __future__ import annotations

import marshal
import os
import signal
import threading
from collections.abc import Callable, Iterator, Sequence

# typing only for type checkers
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any, NoReturn

#: Below this many bytes in all, a process costs more than it saves.
MIN_BYTES = 256 * 1024
#: Processes at most, whatever the number of CPUs.
MAX_PROCESSES = 8


#: CPUs held by processes forked to work beside this one, for as long as they
#: run (:func:`hold`, :func:`release`): the report's drawing process, say.
_held = [0]


def cpus() -> int:
    """The CPUs this process may run on, but those that processes working
    beside it hold (one at least)."""
    try:
        count = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        count = os.cpu_count() or 1
    return max(count - _held[0], 1)


def hold() -> None:
    """A process forked to work beside this one holds a CPU until :func:`release`:
    the work spread by :func:`map_sized` meanwhile takes one process fewer (on
    two CPUs, none), rather than three processes sharing two CPUs."""
    _held[0] += 1


def release() -> None:
    """The process of a :func:`hold` has ended: its CPU is free again."""
    _held[0] = max(_held[0] - 1, 0)


def shares(sizes: Sequence[int], count: int) -> list[list[int]]:
    """Indices of ``sizes`` split into ``count`` shares of about equal total."""
    found: list[list[int]] = [[] for _ in range(count)]
    totals = [0] * count
    for index in sorted(range(len(sizes)), key=sizes.__getitem__, reverse=True):
        lightest = totals.index(min(totals))
        found[lightest].append(index)
        totals[lightest] += sizes[index]
    return [sorted(share) for share in found if share]


def can_fork() -> bool:
    """Whether a process may be forked to work beside this one: ``os.fork``
    exists, more than one CPU is available, and this process runs one thread
    (forking a threaded process can deadlock the child)."""
    return hasattr(os, "fork") and cpus() > 1 and threading.active_count() == 1


def map_sized(
    function: Callable[[Any], Any],
    items: Sequence[Any],
    sizes: Sequence[int],
    meanwhile: Callable[[], object] | None = None,
) -> list:
    """``[function(item) for item in items]``, spread over the CPUs, largest
    ``sizes`` first. ``meanwhile()`` (work that does not depend on the items,
    such as importing what comes next) is done here first, while the other
    processes take items: it is not done in them, and the CPUs they take
    are held (:func:`hold`) while it runs."""
    count = min(cpus(), MAX_PROCESSES, len(items))
    if count < 2 or sum(sizes) < MIN_BYTES or not can_fork():
        if meanwhile is not None:
            meanwhile()
        return [function(item) for item in items]
    queue = _Queue(sorted(range(len(items)), key=sizes.__getitem__, reverse=True))
    results: dict[int, Any] = {}
    children: list[tuple[int, int]] = []
    try:
        for _ in range(count - 1):
            children.append(_fork(function, items, queue))
        if meanwhile is not None:
            _held[0] += len(children)  # their CPUs: work spread meanwhile is spread over the rest
            try:
                meanwhile()
            finally:
                _held[0] -= len(children)
        for index in queue.taken():
            results[index] = function(items[index])
        while children:
            pid, output = children[0]
            results.update(_collect(pid, output))
            children.pop(0)
    finally:
        queue.close()
        for pid, output in children:  # after an error here: no child outlives it
            stop(pid, output)
    return [results[i] if i in results else function(items[i]) for i in range(len(items))]


class _Queue:
    """Items handed out in ``order`` to whichever process asks first: a pipe
    holds a ticket per run of items, and each process reads a ticket at a
    time. Reads of a pipe are whole, so that no two processes share a ticket."""

    #: The bytes of a ticket: the number of its run.
    TICKET = 4
    #: Tickets at most: a pipe holds one page (4 KiB), however little the system allows.
    MOST = 4096 // TICKET

    def __init__(self, order: list[int]) -> None:
        self.order = order
        #: Items per ticket: one, unless there are more items than tickets.
        self.run = -(-len(order) // self.MOST) or 1
        tickets = -(-len(order) // self.run)
        self.output, output_input = os.pipe()
        try:
            os.write(
                output_input, b"".join(t.to_bytes(self.TICKET, "little") for t in range(tickets))
            )
        finally:
            os.close(output_input)  # none is added: a read of the empty pipe ends the taking

    def taken(self) -> Iterator[int]:
        """The indices this process takes, a ticket at a time, until none is left
        (or a read is not whole: no such system is known)."""
        while True:
            ticket = os.read(self.output, self.TICKET)
            if len(ticket) != self.TICKET:
                return
            start = int.from_bytes(ticket, "little") * self.run
            yield from self.order[start : start + self.run]

    def close(self) -> None:
        os.close(self.output)


def fork() -> int:
    """``os.fork()``, with Ctrl-C (SIGINT) held back in the child until it
    calls :func:`forked`, inside the ``try`` whose ``finally`` ends it: a
    Ctrl-C that came earlier would run the parent's code in the child."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    pid = os.fork()
    if pid != 0:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
    else:
        _unheld[:] = [held]
    return pid


#: The signal mask the child of :func:`fork` restores in :func:`forked`.
_unheld: list = []


def forked() -> None:
    """In the child of :func:`fork`, once it is ready: Ctrl-C as before the fork."""
    if _unheld:
        signal.pthread_sigmask(signal.SIG_SETMASK, _unheld.pop())


def _fork(function: Callable[[Any], Any], items: Sequence[Any], queue: _Queue) -> tuple:
    output, output_input = os.pipe()
    pid = fork()
    if pid == 0:  # the child: take items, send what it made, leave without the parent's cleanup
        code = 1
        try:
            forked()
            os.close(output)
            made = [(index, function(items[index])) for index in queue.taken()]
            data = marshal.dumps(made)
            with open(output_input, "wb", closefd=True) as stream:
                stream.write(data)
            code = 0
        finally:
            os._exit(code)
    os.close(output_input)
    return pid, output


def _collect(pid: int, output: int) -> dict[int, Any]:
    """What a child sent: index -> result; empty if it failed. Closes ``output``
    and waits for the child."""
    data = received(pid, output)
    if data is None:
        return {}
    try:
        return dict(marshal.loads(data))
    except (EOFError, ValueError, TypeError):
        return {}


def received(pid: int, output: int) -> bytes | None:
    """All that the forked process ``pid`` wrote to ``output``, once it has
    ended; None if it failed. Closes ``output``."""
    with open(output, "rb", closefd=True) as stream:
        data = stream.read()
    _, status = os.waitpid(pid, 0)
    return data if status == 0 else None


def stop(pid: int, *descriptors: int) -> None:
    """End a forked process whose work is no longer wanted, closing ``descriptors``."""
    try:
        for descriptor in descriptors:
            os.close(descriptor)
        os.kill(pid, 9)
        os.waitpid(pid, 0)
    except OSError:
        pass


class Beside:
    """``work(argument)`` done by a process forked at :meth:`start`, which
    runs ``prepare()`` at once (an import, while this process goes on) and
    then waits for the argument (:meth:`send`); :meth:`result` waits for
    what it made. The process never touches a file: argument and result go
    through pipes, pickled. It is forked only where that is safe and pays
    (:func:`can_fork`); otherwise, and when it fails, the work is done here
    by :meth:`result`, where any error then shows itself. With ``hold``, the
    process holds a CPU (:func:`hold`) from :meth:`start` until it ends, as
    one that works while this one spreads work over the CPUs. As a context
    manager, it is started by ``with`` and stopped at the end of the block."""

    #: Bytes of the length that comes before the argument sent.
    LENGTH_BYTES = 8

    def __init__(
        self,
        work: Callable[[Any], Any],
        prepare: Callable[[], object] | None = None,
        hold: bool = False,
    ) -> None:
        self._work, self._prepare, self._hold = work, prepare, hold
        self._pid: int | None = None
        self._requests: int | None = None  # write end: the argument, to the process
        self._replies: int | None = None  # read end: what the process made
        self._argument: tuple[Any] | None = None
        self._started = False

    def start(self) -> Beside:
        """Fork the process, where one may be (once: again, nothing); this object."""
        if not self._started and can_fork():
            requests_read, requests_write = os.pipe()
            replies_read, replies_write = os.pipe()
            pid = fork()
            if pid == 0:
                self._serve(requests_read, replies_write, requests_write, replies_read)
            os.close(requests_read)
            os.close(replies_write)
            self._pid, self._requests, self._replies = pid, requests_write, replies_read
            if self._hold:
                hold()
        self._started = True
        return self

    @property
    def sent(self) -> bool:
        """Whether :meth:`send` was called."""
        return self._argument is not None

    def send(self, argument: Any) -> None:
        """Have ``work(argument)`` done (see :meth:`result`)."""
        self._argument = (argument,)
        descriptor, self._requests = self._requests, None
        if descriptor is None:
            return
        import pickle  # only where a process is forked

        request = pickle.dumps(argument)
        try:
            with open(descriptor, "wb", closefd=True) as stream:
                stream.write(len(request).to_bytes(self.LENGTH_BYTES, "little") + request)
        except OSError:  # the process is gone: done here
            self.stop()

    def result(self) -> Any:
        """``work(argument)`` of the argument given to :meth:`send`."""
        if self._argument is None:
            raise RuntimeError("Beside.result() before send()")
        pid, replies = self._pid, self._replies
        if pid is not None and replies is not None:
            self._replies = None  # closed by received()
            reply = received(pid, replies)
            self._pid = None  # ended: received() waited for it
            if self._hold:
                release()
            if reply is not None:
                import pickle  # only where a process is forked

                try:
                    return pickle.loads(reply)[0]
                except (pickle.UnpicklingError, EOFError, ValueError, TypeError, IndexError):
                    pass
        return self._work(self._argument[0])

    def stop(self) -> None:
        """End the process, if there is one still: its work is no longer wanted."""
        descriptors = [d for d in (self._requests, self._replies) if d is not None]
        self._requests = self._replies = None
        if self._pid is not None:
            stop(self._pid, *descriptors)
            self._pid = None
            if self._hold:
                release()
        else:
            for descriptor in descriptors:
                os.close(descriptor)

    def __enter__(self) -> Beside:
        return self.start()

    def __exit__(self, *_: object) -> None:
        self.stop()

    def _serve(self, requests: int, replies: int, *unused: int) -> NoReturn:
        """The forked process: prepare, do the work asked for, send back what it
        made; leave without the parent's cleanup (``unused``: the parent's ends
        of the pipes, closed)."""
        code = 1
        try:
            forked()
            for descriptor in unused:
                os.close(descriptor)
            import pickle

            if self._prepare is not None:
                self._prepare()
            with open(requests, "rb", closefd=True) as stream:
                length = int.from_bytes(stream.read(self.LENGTH_BYTES), "little")
                request = stream.read(length)
            if length and len(request) == length:
                reply = pickle.dumps((self._work(pickle.loads(request)),))
                with open(replies, "wb", closefd=True) as stream:
                    stream.write(reply)
                code = 0
        finally:
            os._exit(code)
