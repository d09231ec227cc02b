"""Stage 3, versions: each distinct file version (git blob) read through
:mod:`lensaudit.read` and summarized.

A version is read as any database file is, by :func:`lensaudit.read.read_bytes`,
and its metrics are the pipeline's (:func:`lensaudit.pipeline.file_metrics`).
What the history needs of it is its :class:`Summary`: its error, its
:data:`~.results.COUNT_COLUMNS` and the identity of each audited entry; the
summaries, not the tables, are kept, in the history's index
(:mod:`~.index`).

Versions are read on every core by the reader's own mechanism
(:func:`lensaudit.read.parallel.map_sized`), a file's versions by one
process, in rounds so that progress can be shown: each process reads its
files from git itself (one ``git cat-file`` each) and sends back only
summaries, each identity once with a number the summaries refer to (this
process interns the identities of a file, not of every entry of every
version).

Nearly every lens and entry of a version is one of an earlier version: the
reader's :class:`lensaudit.read.Pieces` and the solver's memo
(:func:`lensaudit.solver.kernel.column_metrics`) skip what was met before.
Where the reader reads a version as nothing but such pieces
(:func:`lensaudit.read.read_pieces`), its summary is that of each piece's
rows, added: a summary counts each row on its own, so that is the summary
of the rows one after the other, and each piece's is kept.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from typing import NamedTuple

from .. import read
from ..pipeline import file_metrics, metric_columns, row_columns
from ..read import parallel
from ..read.records import MODEL_COEFFICIENTS, ROW_FIELDS, STATUS_OK, DistortionEntry
from .audit import BlobAudit, Interner
from .commits import Git, HistoryError
from .results import MODELS

#: A round of versions read between two reports of progress holds about this many
#: bytes. Each round costs a fork and a ``git cat-file`` per process (whose delta
#: caches start cold): the whole Lensfun history (420 MB) is read in one.
ROUND_BYTES = 512 << 20

_FIELD = {name: index for index, name in enumerate(ROW_FIELDS)}
_MAKER, _LENS, _TYPE, _CROP, _MODEL, _FOCAL, _STATUS = (
    _FIELD[name] for name in ("maker", "lens", "type", "crop_factor", "model", "focal", "status")
)
#: model -> (first, last + 1) of its coefficients in a row.
_COEFFICIENTS = {
    model: (_FIELD[names[0]], _FIELD[names[-1]] + 1) for model, names in MODEL_COEFFICIENTS.items()
}
assert all(
    ROW_FIELDS[start:end] == MODEL_COEFFICIENTS[model]
    for model, (start, end) in _COEFFICIENTS.items()
)


def row_identity(row: Sequence) -> tuple:
    """How an audited distortion row (see :data:`~lensaudit.read.records.ROW_FIELDS`)
    is recognised in another revision: maker, lens, crop factor, model, focal
    (mm) and the model's coefficients."""
    model = row[_MODEL]
    start, end = _COEFFICIENTS[model]
    return (row[_MAKER], row[_LENS], row[_CROP], model, row[_FOCAL], tuple(row[start:end]))


def entry_identity(entry: DistortionEntry) -> tuple:
    """:func:`row_identity` of an audited entry."""
    return row_identity(entry[1:])


class Summary(NamedTuple):
    """What one file version holds: its error ("" if none), its
    :data:`~.results.COUNT_COLUMNS`, the identity of each audited entry, in
    file order, and the positions among those of the entries that fold
    inside their image."""

    error: str
    counts: tuple[int, ...]
    identities: list[tuple]
    folding: tuple[int, ...] = ()


def summarize(tables: read.FileTables, metrics: dict[str, list]) -> Summary:
    """The summary of a file version from its tables and metric columns
    (:func:`lensaudit.pipeline.file_metrics`)."""
    return Summary(tables.error, *_rows_summary(tables.distortion, metrics))


def _rows_summary(
    rows: list[tuple], metrics: dict[str, list]
) -> tuple[tuple[int, ...], list[tuple], tuple[int, ...]]:
    """(counts, identities, folding) of a :class:`Summary` of distortion rows and
    their metric columns. Each row counts on its own: the summary of rows one
    after the other is that of each run of them, added (:func:`_added`)."""
    audited = 0
    per_model = dict.fromkeys(MODELS, 0)
    finite_per_model = dict.fromkeys(MODELS, 0)
    folds = folds_rectilinear = folds_paper_rectilinear = 0
    identities = []
    folding = []
    for row, r_max, r_normalized_paper, folds_in_image in zip(
        rows,
        metrics["r_max"],
        metrics["r_normalized_paper"],
        metrics["folds_in_image"],
        strict=True,
    ):
        if row[_STATUS] != STATUS_OK:
            continue
        model = row[_MODEL]
        identities.append(row_identity(row))
        audited += 1
        per_model[model] += 1
        if r_max - r_max != 0:  # infinite (or NaN): nothing folds
            continue
        finite_per_model[model] += 1
        rectilinear = row[_TYPE] == "rectilinear"
        if folds_in_image:
            folds += 1
            folds_rectilinear += rectilinear
            folding.append(len(identities) - 1)
        if rectilinear and r_normalized_paper < 1:
            folds_paper_rectilinear += 1
    counts = (
        len(rows),
        audited,
        *per_model.values(),
        sum(finite_per_model.values()),
        *finite_per_model.values(),
        folds,
        folds_rectilinear,
        folds_paper_rectilinear,
    )
    return counts, identities, tuple(folding)


#: The counts of a :class:`Summary` of no rows.
_NO_COUNTS = _rows_summary([], {"r_max": [], "r_normalized_paper": [], "folds_in_image": []})[0]
#: Pieces whose summary (:func:`_piece_parts`) is kept at most.
MEMO_PIECES = 1 << 16


def _piece_parts(
    pieces: list[list[tuple]], memo: dict[int, tuple], solved: dict[tuple, tuple]
) -> list[tuple[tuple[int, ...], list[tuple], tuple[int, ...]]]:
    """(counts, identities, folding) of the rows of each piece of a file version
    read as pieces (:func:`lensaudit.read.read_pieces`) that has any: the
    version's are theirs added (:func:`_added`). Each is kept in ``memo`` by
    its rows (the same list for the same piece), and solved through the
    solver's memo."""
    if len(memo) > MEMO_PIECES:
        memo.clear()
    parts = []
    for rows in pieces:
        if not rows:
            continue
        kept = memo.get(id(rows))
        if kept is None:
            part = _rows_summary(rows, metric_columns(row_columns(rows), solved))
            memo[id(rows)] = (rows, part)  # rows kept: no other list takes their id
        else:
            part = kept[1]
        parts.append(part)
    return parts


def _added(parts: list[tuple[tuple[int, ...], list, tuple[int, ...]]]) -> tuple:
    """(counts, identities, folding) of runs of rows one after the other, from
    those of each run (their identities, or numbers that stand for them)."""
    if not parts:
        return _NO_COUNTS, [], ()
    identities: list = []
    folding: list[int] = []
    for _, found, folds in parts:
        if folds:
            folding += [len(identities) + position for position in folds]
        identities += found
    counts = tuple(map(sum, zip(*[counts for counts, _, _ in parts], strict=True)))
    return counts, identities, tuple(folding)


def read_versions(
    git: Git,
    blobs: Sequence[str],
    names: dict[str, str],
    interner: Interner,
    progress: Callable[[int], None] | None = None,
    meanwhile: Callable[[], object] | None = None,
) -> dict[str, BlobAudit]:
    """The audits of file versions (``blobs``, shown as ``names``), read on
    every core, their identities interned by ``interner``. ``progress(done)``
    is called after each round with the number read so far; ``meanwhile()``
    is done by this process while the others start reading (see
    :func:`lensaudit.read.parallel.map_sized`). Raises
    :class:`~.commits.HistoryError` when git cannot give a version."""
    sizes = []
    for blob, size in zip(blobs, git.object_sizes(blobs), strict=True):
        if size is None:
            raise HistoryError(f"git cannot read object {blob} of {git.repository}")
        sizes.append(size)
    # Most lenses and entries of a version are an earlier version's: what this
    # process learns in a round is known to it in the next.
    pieces, memo, solved = read.Pieces(), {}, {}
    read_batch = partial(_read_batch, git, names, pieces, memo, solved)
    found: dict[str, BlobAudit] = {}
    for round_blobs, round_sizes in _rounds(blobs, sizes):
        batches, batch_sizes = _by_file(round_blobs, round_sizes, names)
        made = parallel.map_sized(read_batch, batches, batch_sizes, meanwhile)
        meanwhile = None
        for batch, (identities, summaries) in zip(batches, made, strict=True):
            numbers = list(map(interner, identities))
            for blob, (error, counts, local, folding) in zip(batch, summaries, strict=True):
                idents = tuple(map(numbers.__getitem__, local))
                found[blob] = BlobAudit(error, counts, idents, tuple(idents[i] for i in folding))
        if progress is not None:
            progress(len(found))
    if meanwhile is not None:  # no round
        meanwhile()
        if progress is not None:
            progress(0)
    return found


def _by_file(
    blobs: Sequence[str], sizes: Sequence[int], names: dict[str, str]
) -> tuple[list[list[str]], list[int]]:
    """``blobs`` by file, and the size of each file's: every version of a file is
    read by one process, which then learns each of its pieces once (the memos
    are a process's own)."""
    files: dict[str, tuple[list[str], list[int]]] = {}
    for blob, size in zip(blobs, sizes, strict=True):
        versions, total = files.setdefault(names[blob], ([], [0]))
        versions.append(blob)
        total[0] += size
    return [versions for versions, _ in files.values()], [t[0] for _, t in files.values()]


def _rounds(blobs: Sequence[str], sizes: Sequence[int]) -> list[tuple[list[str], list[int]]]:
    """The versions and their sizes in rounds of about :data:`ROUND_BYTES` each."""
    rounds: list[tuple[list[str], list[int]]] = []
    total = ROUND_BYTES
    for blob, size in zip(blobs, sizes, strict=True):
        if total >= ROUND_BYTES:
            rounds.append(([], []))
            total = 0
        rounds[-1][0].append(blob)
        rounds[-1][1].append(size)
        total += size
    return rounds


def _read_batch(
    git: Git,
    names: dict[str, str],
    pieces: read.Pieces,
    memo: dict[int, tuple],
    solved: dict[tuple, tuple],
    batch: list[str],
) -> tuple[list[tuple], list]:
    """The summaries of a batch of versions (one file's, oldest first), as
    plain data: the identities met, each once, and the summaries, their
    identities given as positions in that list. ``pieces``, ``memo`` and ``solved`` are the
    reader's memo, that of the summary of each piece, and the solver's."""
    known: dict[tuple, int] = {}  # identity -> its position among those met
    numbered: dict[int, tuple[list[tuple], list[int]]] = {}  # of a piece's identities

    def numbers_of(identities: list[tuple]) -> list[int]:
        found = numbered.get(id(identities))
        if found is None or found[0] is not identities:
            found = numbered[id(identities)] = (identities, numbers(identities))
        return found[1]

    def numbers(identities: list[tuple]) -> list[int]:
        return [known.setdefault(identity, len(known)) for identity in identities]

    summaries = []
    for blob, answer in zip(batch, git.objects(batch), strict=True):
        if answer is None:
            raise HistoryError(f"git cannot read object {blob} of {git.repository}")
        piece_rows = read.read_pieces(answer[2], pieces)
        if piece_rows is not None:
            parts = _piece_parts(piece_rows, memo, solved)
            counts, local, folding = _added([(c, numbers_of(i), f) for c, i, f in parts])
            summaries.append(("", counts, local, folding))
        else:
            tables = read.read_bytes(answer[2], names[blob], pieces=pieces)
            summary = summarize(tables, file_metrics(tables, None, solved))
            summaries.append(
                (summary.error, summary.counts, numbers(summary.identities), summary.folding)
            )
    return list(known), summaries
