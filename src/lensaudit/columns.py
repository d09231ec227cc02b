"""The columns of an audit, in output order, and how their numbers are written.

The pipeline, the parse cache, the summary and the output formats all name
columns; they take the names from here, so that none of them has to import
another for it.
"""

from __future__ import annotations

from collections.abc import Sequence

#: The columns every audit (distortion, vignetting, TCA) starts with: where the
#: entry is, its lens, its model and focal length.
LENS_COLUMNS = (
    "file", "line", "maker", "lens", "type", "crop_factor", "aspect_ratio", "model", "focal",
)  # fmt: skip
#: Those of them that hold numbers.
LENS_FLOAT_COLUMNS = frozenset({"crop_factor", "aspect_ratio", "focal"})
#: The columns every audit ends with.
STATUS_COLUMNS = ("status", "message")

#: Columns computed by the audit; the others are read from the database.
METRIC_COLUMNS = (
    "r_max", "d_max", "tail", "r_corner", "r_normalized", "r_corner_paper",
    "r_normalized_paper", "folds_in_image",
)  # fmt: skip
#: r_normalized below which a model folds too near its image: ``check`` warns
#: (fold-near-image) below it, and ``fix`` refits a model to reach at least
#: this many times the image radius before it folds. One constant, so that an
#: entry ``fix`` fixes passes ``check`` with no fold finding at any severity.
FOLD_MARGIN = 1.1

#: Output columns, in order, for every format (CSV header, JSON keys, DataFrame).
COLUMNS = (
    *LENS_COLUMNS, "real_focal", "a", "b", "c", "k1", "k2", *METRIC_COLUMNS, *STATUS_COLUMNS,
)  # fmt: skip
ENTRY_COLUMNS = tuple(name for name in COLUMNS if name not in METRIC_COLUMNS)
#: Columns holding numbers (written as shortest round-trip floats, inf, or empty).
FLOAT_COLUMNS = frozenset(COLUMNS) - {
    "file", "line", "maker", "lens", "type", "model", "tail", "folds_in_image", "status",
    "message",
}  # fmt: skip
#: The metric columns held as small integers: ``tail`` -1/0/1, ``folds_in_image`` 0/1.
METRIC_FLAG_COLUMNS = ("tail", "folds_in_image")
#: The metric columns that hold floats.
METRIC_FLOAT_COLUMNS = tuple(name for name in METRIC_COLUMNS if name not in METRIC_FLAG_COLUMNS)

_FIRST_METRIC = COLUMNS.index(METRIC_COLUMNS[0])
#: The columns of a row before its metrics, and after them: the metrics are one
#: run of columns, so a row is its entry's text, the metrics, then the rest.
LEADING_COLUMNS = COLUMNS[:_FIRST_METRIC]
TRAILING_COLUMNS = COLUMNS[_FIRST_METRIC + len(METRIC_COLUMNS) :]
assert COLUMNS[_FIRST_METRIC : _FIRST_METRIC + len(METRIC_COLUMNS)] == METRIC_COLUMNS

#: ``tail`` as written: the sign of D(r) beyond r_max, or "" where there is none.
TAIL_NAMES = {1: "positive", -1: "negative", 0: ""}


def format_float(value: float) -> str:
    """A float as the text formats write it: shortest round-trip, inf, or empty for NaN."""
    text = repr(value)
    return "" if text == "nan" else text


def float_texts(values: Sequence[float], special: dict[str, str] | None = None) -> list[str]:
    """``repr`` of each float (shortest round-trip, ``inf``, ``nan``), at C speed;
    texts that are keys of ``special`` are replaced by their value there."""
    distinct = dict.fromkeys(values)
    # Writing a float (repr) costs ten times a dict lookup: a column whose values
    # repeat (an image corner, a crop factor, inf, a model shared by several
    # focal lengths) is written once per value.
    if 3 * len(distinct) <= 2 * len(values):
        known = dict(zip(distinct, map(repr, distinct), strict=True))
        if special and not special.keys().isdisjoint(known.values()):
            known.update({value: special[t] for value, t in known.items() if t in special})
        texts = list(map(known.__getitem__, values))
        if 0.0 in known:  # 0.0 and -0.0 are one key but two texts
            for index, value in enumerate(values):
                if value == 0.0:
                    texts[index] = repr(value)
        return texts
    texts = list(map(repr, values))
    if special and not special.keys().isdisjoint(texts):
        texts = [special.get(text, text) for text in texts]
    return texts


def format_floats(values: Sequence[float]) -> list[str]:
    """:func:`format_float` over a list, at C speed for the common case."""
    return float_texts(values, _EMPTY_NAN)


_EMPTY_NAN = {"nan": ""}
