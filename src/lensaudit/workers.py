"""Parse database files in worker processes while the calling process does other work.

Parsing the XML is most of a fresh ``lensaudit scan``. Where more than one
CPU is available, :func:`parse_all` forks worker processes, which parse
files while the calling process does its own work; then the calling process
parses files too, and collects the workers' results once none are left.
Files are handed out one at a time, largest first, through a pipe, so that
whichever process is free takes the next one. Results come back as
:mod:`marshal` data (the packed columns of :mod:`lensaudit.cache`, not entry
objects), each marshalled as soon as it is made.

Workers are used only where they are safe and pay: ``os.fork`` exists, the
process runs a single thread (forking a threaded process can deadlock the
child), more than one CPU is available to it, and there is enough to parse.
Otherwise the files are parsed in a thread, as libxml2 parses without
holding the GIL. A worker that fails costs only time: whatever it did not
return is parsed by the calling process, which then meets any error itself.
"""

from __future__ import annotations

import marshal
import os
import sys
from collections.abc import Callable, Iterator
from itertools import accumulate
from pathlib import Path

# typing only for type checkers: a scan from the cache never imports it.
TYPE_CHECKING = False
if TYPE_CHECKING:
    from typing import Any, NoReturn, TypeVar

    T = TypeVar("T")
    J = TypeVar("J")  # a piece of work: a Job, or any value ``parse`` takes

#: Below this many bytes to parse, a worker costs more than it saves.
MIN_BYTES = 256 * 1024
#: Worker processes at most, whatever the number of CPUs.
MAX_WORKERS = 8
#: Pieces of work at most: 4 bytes each in the queue, which must fit in a pipe at once.
_MAX_TASKS = 1024
#: Results a worker can send back at most (one per job; a guard against garbage).
_MAX_RESULTS = 1 << 24
#: Buffers one os.writev call takes at most (the system's IOV_MAX is at least 1024).
_IOV_MAX = 1024


class Job:
    """A file to parse: its absolute ``path``, display ``name``, and its bytes if
    already read (``data``); ``size``, if given, is the number of bytes it will
    have when read (for contents that are not files, such as git objects)."""

    __slots__ = ("path", "name", "data", "size")

    def __init__(
        self, path: Path, name: str, data: bytes | None = None, size: int | None = None
    ) -> None:
        self.path = path
        self.name = name
        self.data = data
        self.size = size


def parse_all(
    jobs: list[Job],
    parse: Callable[[Job], T],
    meanwhile: Callable[[], Any],
    progress: Callable[[int, int], None] | None = None,
) -> list[T]:
    """``[parse(job) for job in jobs]``, computed while ``meanwhile()`` runs here.

    ``parse`` must be deterministic and its results :mod:`marshal` data, as
    it may run in a forked process. Exceptions of ``meanwhile`` and of
    ``parse`` (as met in this process) are raised. ``progress(done, total)``,
    if given, is called in this process as jobs are taken up (by any
    process), and once all are done.
    """
    sizes = [_size(job) for job in jobs] if jobs and _can_fork() else []
    workers = min(_cpus() - 1, len(jobs) - 1, MAX_WORKERS) if sum(sizes) >= MIN_BYTES else 0
    if workers < 1:
        results = _in_thread(jobs, parse, meanwhile, progress)
    else:
        results = _in_processes(jobs, sizes, workers, parse, meanwhile, progress)
    if progress is not None and jobs:
        progress(len(jobs), len(jobs))
    return results


def in_parallel(tasks: list[Callable[[], T]]) -> list[T]:
    """``[task() for task in tasks]``, the tasks shared between this process and
    forked workers where that is safe and more than one CPU is free, else run
    one after another here (never in threads: a task may use what a thread
    must not share). Results must be :mod:`marshal` data; a task whose worker
    fails runs here."""
    workers = min(_cpus() - 1, len(tasks) - 1, MAX_WORKERS)
    if workers < 1 or not _can_fork():
        return [task() for task in tasks]
    # The tasks are the jobs, each as large as the next.
    return _in_processes(tasks, [1] * len(tasks), workers, _run, lambda: None, None)


def _run(task: Callable[[], T]) -> T:
    return task()


def _can_fork() -> bool:
    if not hasattr(os, "fork"):
        return False
    threading = sys.modules.get("threading")
    if threading is not None and threading.active_count() > 1:
        return False
    try:  # threads started by C code (a BLAS pool) count too
        return len(os.listdir("/proc/self/task")) == 1
    except OSError:  # no /proc: numpy is what would have started some
        return "numpy" not in sys.modules


def _cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def _size(job: Job) -> int:
    if job.data is not None:
        return len(job.data)
    if job.size is not None:
        return job.size
    try:
        return os.stat(job.path).st_size
    except OSError:
        return 0


def _in_thread(
    jobs: list[Job],
    parse: Callable[[Job], T],
    meanwhile: Callable[[], Any],
    progress: Callable[[int, int], None] | None,
) -> list[T]:
    if not jobs:
        meanwhile()
        return []
    import threading

    outcome: dict[str, Any] = {}

    def work() -> None:
        try:
            results = []
            for job in jobs:
                results.append(parse(job))
                if progress is not None:  # this thread alone reports
                    progress(len(results), len(jobs))
            outcome["result"] = results
        except BaseException as error:  # handed to the caller, not lost in the thread
            outcome["error"] = error

    thread = threading.Thread(target=work, name="lensaudit-parse", daemon=True)
    thread.start()
    try:
        meanwhile()
    finally:
        thread.join()
    if "error" in outcome:
        raise outcome["error"]
    return outcome["result"]


def _in_processes(
    jobs: list[J],
    sizes: list[int],
    workers: int,
    parse: Callable[[J], T],
    meanwhile: Callable[[], Any],
    progress: Callable[[int, int], None] | None,
) -> list[T]:
    # Largest first, so that the last pieces, taken by whoever is free, are small.
    order = sorted(range(len(jobs)), key=sizes.__getitem__, reverse=True)
    count = min(len(order), _MAX_TASKS)
    tasks = [order[start::count] for start in range(count)]
    queue, queue_input = os.pipe()
    try:
        os.write(queue_input, b"".join(n.to_bytes(4, "little") for n in range(count)))
    finally:
        os.close(queue_input)  # an empty queue then reads as its end
    children: dict[int, int] = {}  # pid -> read end of its results
    results: dict[int, T] = {}
    try:
        for _ in range(workers):
            output, output_input = os.pipe()
            _widen(output)
            pid = os.fork()
            if pid == 0:
                os.close(output)
                _work(queue, output_input, tasks, jobs, parse)
            os.close(output_input)
            children[pid] = output
        meanwhile()
        taken = _taken(queue, tasks) if progress is not None else None
        for index in _take(queue, tasks):
            results[index] = parse(jobs[index])
            if taken is not None:
                progress(taken(), len(jobs))
        for pid, output in list(children.items()):
            results.update(_collect(output))
            os.close(output)
            del children[pid]
            os.waitpid(pid, 0)
    finally:
        os.close(queue)
        _stop(children)
    # What a worker did not return (it failed, or was killed) is parsed here.
    return [results[i] if i in results else parse(jobs[i]) for i in range(len(jobs))]


def _widen(pipe: int) -> None:
    """Let the pipe hold a worker's results whole, where the system allows it."""
    try:
        import fcntl

        fcntl.fcntl(pipe, fcntl.F_SETPIPE_SZ, 1 << 20)
    except (ImportError, AttributeError, OSError):
        pass


def _taken(queue: int, tasks: list[list[int]]) -> Callable[[], int]:
    """How many jobs have been taken from the queue so far, by any process: tasks
    are taken in order, and the bytes left in the pipe tell how many remain."""
    import fcntl
    import termios

    before = [0, *accumulate(map(len, tasks))]  # jobs in the tasks before each
    left = bytearray(4)

    def count() -> int:
        try:
            fcntl.ioctl(queue, termios.FIONREAD, left)
        except OSError:
            return 0
        return before[len(tasks) - int.from_bytes(left, sys.byteorder) // 4]

    return count


def _take(queue: int, tasks: list[list[int]]) -> Iterator[int]:
    """Indices of the jobs of each task taken from the queue, until it is empty."""
    while True:
        number = os.read(queue, 4)
        if len(number) != 4:  # reads of 4 bytes from a pipe written in 4s are whole
            return
        yield from tasks[int.from_bytes(number, "little")]


def _work(
    queue: int, output: int, tasks: list[list[int]], jobs: list[Job], parse: Callable[[Job], T]
) -> NoReturn:
    """A worker's life: parse jobs from the queue, send the results, exit."""
    code = 1
    try:
        import gc

        gc.disable()  # a short life, ended by os._exit: nothing to collect
        # Each result marshalled as soon as it is made, not all at the end,
        # when the caller is waiting for them.
        done = [marshal.dumps((index, parse(jobs[index]))) for index in _take(queue, tasks)]
        sizes = b"".join(len(result).to_bytes(8, "little") for result in done)
        _write_all(output, [len(done).to_bytes(8, "little"), sizes, *done])
        # Closed now, not at exit: the caller reads to the end of the pipe,
        # which would otherwise wait for this process's memory to be freed.
        os.close(output)
        code = 0
    except BaseException:  # noqa: S110  (the caller parses what is missing)
        pass
    finally:
        # Not sys.exit: the parent's cleanup, atexit handlers and buffered
        # output belong to the parent.
        os._exit(code)


def _write_all(output: int, pieces: list[bytes]) -> None:
    """Write ``pieces`` to ``output`` in order, without joining them first."""
    views = [memoryview(piece) for piece in pieces if piece]
    while views:
        written = os.writev(output, views[:_IOV_MAX])
        while views and written >= len(views[0]):
            written -= len(views.pop(0))
        if written:
            views[0] = views[0][written:]


def _collect(output: int) -> dict[int, Any]:
    """The results a worker sent: job index -> result; empty if it failed.

    The worker sends their number, their sizes, then each as :mod:`marshal`
    data; they are read into one buffer, unmarshalled piece by piece.
    """
    head = _read_exactly(output, bytearray(8))
    count = int.from_bytes(head, "little") if head is not None else -1
    sizes = _read_exactly(output, bytearray(8 * count)) if 0 <= count <= _MAX_RESULTS else None
    if sizes is None:
        return {}
    ends = list(
        accumulate(int.from_bytes(sizes[i : i + 8], "little") for i in range(0, len(sizes), 8))
    )
    buffer = _read_exactly(output, bytearray(ends[-1] if ends else 0))
    if buffer is None:
        return {}
    view = memoryview(buffer)
    try:
        return dict(
            marshal.loads(view[start:end]) for start, end in zip([0, *ends[:-1]], ends, strict=True)
        )
    except (EOFError, ValueError, TypeError):
        return {}


def _read_exactly(source: int, buffer: bytearray) -> bytearray | None:
    """``buffer`` filled from ``source``, or None if it ends first."""
    view = memoryview(buffer)
    position = 0
    while position < len(buffer):
        count = os.readv(source, [view[position:]])
        if count == 0:
            return None
        position += count
    return buffer


def _stop(children: dict[int, int]) -> None:
    """End and reap workers whose results were not collected (an error here)."""
    if not children:
        return
    import signal

    for pid, output in children.items():
        os.close(output)
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
        try:
            os.waitpid(pid, 0)
        except OSError:
            pass
