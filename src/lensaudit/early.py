"""Start parsing a database while ``lensaudit scan`` is still reading its command line.

A cold scan spends its first tens of milliseconds importing click and
reading its options, with any second CPU idle. When the command is ``scan``,
the console command calls :func:`start` before anything else: it forks a
worker that guesses from the words of the command line which files the scan
will parse (its paths, output format, and whether the cache is on), lists
them, and parses them largest first, taking each from a queue that the scan
can take from too. With the cache on, a database the cache has met before
is left alone: the scan is likely to find it there.

When the scan reaches its parsing (:func:`lensaudit.workers.parse_all`), it
calls :func:`adopt` with how it parses. If the worker parses the same way,
the scan takes files from the same queue: each file it needs it parses
itself, and takes the worker's results for those the worker took; a file
the worker listed that the scan does not need is left to the worker, and one
it did not list is parsed by the scan. Results are matched to files by path
and carry the digest of the bytes they were made from, as any worker's do.
A worker that guessed wrong, or is never adopted (bad usage, nothing to
parse), is stopped: a wrong guess costs only the other CPU's time, never a
wrong result.

The guess reads the options of ``lensaudit scan`` from :data:`SCAN_OPTIONS`,
which a test keeps equal to the command's own.
"""

from __future__ import annotations

import marshal
import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NoReturn

#: The options of ``lensaudit scan``: name -> the setting it gives (flags) or
#: names (options that take a value), as the guess reads them.
SCAN_OPTIONS: dict[str, str] = {
    "-f": "format",
    "--format": "format",
    "-k": "kind",
    "--kind": "kind",
    "-o": "output",
    "--output": "output",
    "--cache": "cache",
    "--no-cache": "no-cache",
}
#: Of those, the flags (the others take a value).
SCAN_FLAGS = ("--cache", "--no-cache")


@dataclass(frozen=True, slots=True)
class Guess:
    """What a scan command line asks to parse: database paths as given (none:
    the default database), the row formats to render, whether the cache is on."""

    paths: tuple[str, ...]
    formats: tuple[str, ...]
    cache: bool


def guess(words: list[str]) -> Guess | None:
    """What ``lensaudit scan WORDS...`` will parse, or None if that is not
    plain to see (help asked for, another kind, an option unknown here)."""
    from .formats import FORMATS, ROW_FORMATS

    paths: list[str] = []
    settings = {"format": "table", "kind": "distortion", "cache": True}
    rest = iter(words)
    for word in rest:
        if word == "--":
            paths += rest
            break
        if not word.startswith("-") or word == "-":
            paths.append(word)
            continue
        name, equals, value = word.partition("=")
        if name not in SCAN_OPTIONS and name[:2] in SCAN_OPTIONS and not name.startswith("--"):
            name, equals, value = name[:2], "=", word[2:]  # -fcsv
        setting = SCAN_OPTIONS.get(name)
        if setting is None:
            return None
        if name in SCAN_FLAGS:
            if equals:
                return None
            settings["cache"] = setting == "cache"
            continue
        if not equals:
            value = next(rest, None)
            if value is None:
                return None
        settings[setting] = value
    output_format = settings["format"]
    if settings["kind"] != "distortion" or output_format not in FORMATS:
        return None
    formats = tuple(name for name in ROW_FORMATS if name == output_format)
    return Guess(tuple(paths), formats, bool(settings["cache"]))


@dataclass(slots=True)
class _Worker:
    """The worker started by :func:`start`, seen from this process."""

    pid: int
    manifest: int  # read end: the worker's guess and jobs, then its end
    queue: int  # read end of the queue shared with the worker
    results: int  # read end of the worker's results


@dataclass(frozen=True, slots=True)
class Adopted:
    """A worker adopted by :func:`adopt`: its jobs (file paths, as bytes), its
    tasks (lists of indices into ``paths``) and the queue they are taken from.

    :meth:`results` waits for the worker and gives what it parsed, by index
    into ``paths`` (nothing if it failed).
    """

    pid: int
    queue: int
    paths: list[bytes]
    tasks: list[list[int]]
    output: int

    def results(self) -> dict[int, Any]:
        from .workers import collect

        try:
            return collect(self.output)
        finally:
            os.close(self.output)
            _reap(self.pid)

    def abandon(self) -> None:
        """Stop the worker, its results unread (call instead of :meth:`results`)."""
        os.close(self.output)
        _kill(self.pid)


_started: _Worker | None = None


def start(words: list[str]) -> None:
    """Fork the worker for ``lensaudit scan WORDS...``, if forking is possible
    and pays (a second CPU); call before importing anything else."""
    global _started
    if _started is not None or not hasattr(os, "fork") or _cpus() < 2:
        return
    manifest, manifest_input = os.pipe()
    queue, queue_input = os.pipe()
    results, results_input = os.pipe()
    pid = os.fork()
    if pid == 0:
        for end in (manifest, results):
            os.close(end)
        _work(words, manifest_input, queue, queue_input, results_input)
    for end in (manifest_input, queue_input, results_input):
        os.close(end)
    _started = _Worker(pid, manifest, queue, results)


def adopt(formats: tuple[str, ...], cache: bool) -> Adopted | None:
    """The worker, if one was started and parses files as asked: rendering
    ``formats``, and with digests when ``cache`` is on; else None (and any
    worker is stopped)."""
    global _started
    worker, _started = _started, None
    if worker is None:
        return None
    try:
        with os.fdopen(worker.manifest, "rb") as stream:
            data = stream.read()
        said, paths, tasks = marshal.loads(data)
        if said == (formats, cache) and paths:
            return Adopted(worker.pid, worker.queue, paths, tasks, worker.results)
    except (OSError, EOFError, ValueError, TypeError):  # the worker failed: parse here
        pass
    _end(worker)
    return None


def stop() -> None:
    """Stop a worker that was never adopted (the command did not get to parse)."""
    global _started
    worker, _started = _started, None
    if worker is not None:
        os.close(worker.manifest)
        _end(worker)


def _end(worker: _Worker) -> None:
    for end in (worker.queue, worker.results):
        os.close(end)
    _kill(worker.pid)


def _kill(pid: int) -> None:
    import signal

    try:
        os.kill(pid, signal.SIGKILL)
    except OSError:
        pass
    _reap(pid)


def _reap(pid: int) -> None:
    try:
        os.waitpid(pid, 0)
    except OSError:
        pass


def _cpus() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def _work(words: list[str], manifest: int, queue: int, queue_input: int, output: int) -> NoReturn:
    """The worker's life: guess, list the jobs, queue them, parse, send, exit."""
    code = 1
    try:
        import gc

        gc.disable()  # a short life, ended by os._exit: nothing to collect
        said: tuple = ((), False)
        jobs: list = []
        found = guess(words)
        if found is not None:
            said = (found.formats, found.cache)
            jobs = _jobs(found)
        from .workers import MIN_BYTES, send, size, tasks_of

        sizes = [size(job) for job in jobs]
        if sum(sizes) < MIN_BYTES:
            jobs = sizes = []
        tasks = tasks_of(sizes)
        with os.fdopen(manifest, "wb") as stream:
            stream.write(marshal.dumps((said, [os.fsencode(job.path) for job in jobs], tasks)))
        os.write(queue_input, b"".join(n.to_bytes(4, "little") for n in range(len(tasks))))
        os.close(queue_input)  # an empty queue then reads as its end
        if jobs:
            parse = _parser(*said)
            send(output, queue, tasks, jobs, parse)
        code = 0
    except BaseException:  # noqa: S110  (the scan parses what is missing)
        pass
    finally:
        # Not sys.exit: the parent's cleanup and buffered output belong to the parent.
        os._exit(code)


def _jobs(found: Guess) -> list:
    """The files the scan will parse: every file of the database, unless the
    cache is on and has met these files before (then the scan is likely to
    find them there: reading the cache here too would only double that work)."""
    from . import loader
    from .database import resolve_paths
    from .workers import Job

    targets = loader.expand(resolve_paths(list(found.paths) or None))
    if found.cache:
        from .cache import may_know

        if may_know([path for path, _ in targets]):
            return []
    return [Job(path, name) for path, name in targets]


def _parser(formats: tuple[str, ...], cache: bool) -> Callable[[Any], Any]:
    from .pipeline import file_parser

    return file_parser(formats, digests=cache)
