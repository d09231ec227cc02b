"""``report.html``: one self-contained page (no external CSS, JS, fonts or images).

Everything taken from the database (makers, lens names, messages, file
names) is untrusted: it is HTML-escaped in the markup, and in the entry data
every ``<``, ``>`` and ``&`` is a JSON escape, so nothing can close the data
block. The page's Content-Security-Policy allows only its own script (by
hash), loads nothing, and so would not run an injected script either.
"""

from __future__ import annotations

import base64
import hashlib
import json
import math
import re
from html import escape
from typing import TYPE_CHECKING, Any

from ..read.records import MODEL_COEFFICIENTS
from ..version import __version__
from . import curves
from .tables import TABLE1_CAPTION, TABLE1_HEADER, TABLE2_CAPTION, TABLE2_HEADER

if TYPE_CHECKING:
    from ..pipeline import Audit
    from .histogram import Histogram
    from .paper import Comparison
    from .provenance import Provenance

#: Entry-table columns: (key, heading, kind); kind "num" sorts numerically.
ENTRY_COLUMNS = (
    ("where", "file:line", "text"),
    ("maker", "maker", "text"),
    ("lens", "lens", "text"),
    ("type", "type", "text"),
    ("model", "model", "text"),
    ("focal", "focal mm", "num"),
    ("crop_factor", "crop", "num"),
    ("aspect_ratio", "aspect", "num"),
    ("coefficients", "coefficients", "text"),
    ("r_max", "r_max", "num"),
    ("d_max", "D(r_max)", "num"),
    ("r_normalized", "r_normalized", "num"),
    ("r_normalized_paper", "r_normalized (paper's units)", "num"),
    ("tail", "tail", "text"),
    ("folds_in_image", "folds in image", "text"),
    ("status", "status", "text"),
)

# The entry table's box may be wider than the text (up to 1400 px, centred)
# and scrolls on its own, both ways with a sticky heading, so that the page
# itself never scrolls sideways. A file:line (class "where") never breaks at
# its hyphens: in a narrow window the table scrolls instead. The width the
# longest (compact-konica-minolta.xml:NNN) takes is won back by narrower
# padding and headings, so that the whole table still fits at 1400 px.
# A fold's sketch takes its card's width (two cards a row at 1400 px, one at
# 800 px), up to 520 px.
_CSS = """
body{font:15px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;color:#1b1b1b}
main{max-width:1200px;margin:0 auto;padding:1em 1.5em 3em}
h1{font-size:1.6em;margin:.6em 0 .2em}h2{margin-top:1.8em;border-bottom:1px solid #ddd}
dl.provenance{display:grid;grid-template-columns:max-content 1fr;gap:.2em 1em}
dl.provenance dt{font-weight:600}dl.provenance dd{margin:0;word-break:break-all}
table{border-collapse:collapse;font-variant-numeric:tabular-nums}
th,td{padding:.25em .6em;border-bottom:1px solid #e3e3e3;text-align:left}
td.n,th.n{text-align:right}caption{text-align:left;padding:.3em 0;color:#444}
.figure svg{max-width:100%;height:auto}.note{color:#555;font-size:.92em}
.folds{display:grid;grid-template-columns:repeat(auto-fill,minmax(min(100%,440px),1fr));gap:1em}
.fold{border:1px solid #ddd;border-radius:6px;padding:.6em .8em;min-width:0}
.fold svg{display:block;width:100%;max-width:520px;height:auto}.where{white-space:nowrap}
.fold h3{font-size:1em;margin:.1em 0 .4em}.fold dl{display:grid;
grid-template-columns:max-content 1fr;gap:0 .8em;margin:.4em 0 0;font-size:.9em}
.fold dd{margin:0}.controls{display:flex;flex-wrap:wrap;gap:.6em 1.2em;align-items:center;
margin:.6em 0}.scroll{overflow-x:auto;max-width:100%}
.entries-box{overflow:auto;max-height:85vh;border:1px solid #e3e3e3;
width:min(calc(100vw - 3em),1400px);position:relative;left:50%;transform:translateX(-50%)}
#entries{font-size:.85em;width:100%}#entries th,#entries td{padding:.25em .3em}
#entries th{font-size:.92em;cursor:pointer;position:sticky;top:0;z-index:1;background:#f6f6f6;
user-select:none}
#entries th[aria-sort=ascending]::after{content:" \\25B2"}
#entries th[aria-sort=descending]::after{content:" \\25BC"}
#entries tr.fold-row td{background:#fdecea}code{font-size:.92em}
"""

# The page's only script: builds, filters and sorts the entry table from the
# JSON data block. State lives in the URL fragment (#q=...&sort=...&dir=...),
# so that a filtered, sorted view can be linked to.
_SCRIPT = r"""
(function () {
  "use strict";
  var data = JSON.parse(document.getElementById("entries-data").textContent);
  var keys = data.columns.map(function (c) { return c[0]; });
  var numeric = data.columns.map(function (c) { return c[2] === "num"; });
  var table = document.getElementById("entries");
  var body = table.tBodies[0];
  var headers = table.tHead.rows[0].cells;
  var inputs = {
    q: document.getElementById("filter-text"),
    model: document.getElementById("filter-model"),
    status: document.getElementById("filter-status"),
    folds: document.getElementById("filter-folds"),
    finite: document.getElementById("filter-finite")
  };
  var state = {q: "", model: "", status: "", folds: false, finite: false, sort: "", dir: "asc"};
  var searchable = ["where", "maker", "lens", "type", "model", "status"].map(function (k) {
    return keys.indexOf(k);
  });
  var col = function (name) { return keys.indexOf(name); };

  function readHash() {
    var params = new URLSearchParams(window.location.hash.replace(/^#/, ""));
    state.q = params.get("q") || "";
    state.model = params.get("model") || "";
    state.status = params.get("status") || "";
    state.folds = params.get("folds") === "1";
    state.finite = params.get("finite") === "1";
    state.sort = keys.indexOf(params.get("sort")) >= 0 ? params.get("sort") : "";
    state.dir = params.get("dir") === "desc" ? "desc" : "asc";
    inputs.q.value = state.q;
    inputs.model.value = state.model;
    inputs.status.value = state.status;
    inputs.folds.checked = state.folds;
    inputs.finite.checked = state.finite;
  }

  function writeHash() {
    var params = new URLSearchParams();
    ["q", "model", "status", "sort"].forEach(function (k) {
      if (state[k]) params.set(k, state[k]);
    });
    if (state.folds) params.set("folds", "1");
    if (state.finite) params.set("finite", "1");
    if (state.sort && state.dir === "desc") params.set("dir", "desc");
    try { history.replaceState(null, "", "#" + params.toString()); } catch (e) { /* file:// */ }
  }

  function number(value) {
    if (value === null || value === "") return NaN;
    if (value === "inf") return Infinity;
    if (value === "-inf") return -Infinity;
    return value;
  }

  function show(value, index) {
    if (value === null) return "";
    if (value === true) return "yes";
    if (value === false) return "no";
    if (!numeric[index]) return String(value);
    if (value === "inf") return "\u221e";
    if (value === "-inf") return "-\u221e";
    var size = Math.abs(value);
    if (value !== 0 && (size >= 1e5 || size < 1e-3)) return value.toExponential(3);
    return String(Number(value.toPrecision(5)));
  }

  function matches(row) {
    if (state.model && row[col("model")] !== state.model) return false;
    if (state.status && row[col("status")] !== state.status) return false;
    if (state.folds && row[col("folds_in_image")] !== true) return false;
    if (state.finite && !isFinite(number(row[col("r_max")]))) return false;
    if (!state.q) return true;
    var words = state.q.toLowerCase().split(/\s+/).filter(Boolean);
    var text = searchable.map(function (i) { return String(row[i]); }).join(" ").toLowerCase();
    return words.every(function (w) { return text.indexOf(w) >= 0; });
  }

  function compare(index) {
    var sign = state.dir === "desc" ? -1 : 1;
    return function (a, b) {
      var x = a[index], y = b[index];
      if (numeric[index]) {
        var p = number(x), q = number(y);
        if (isNaN(p) || isNaN(q)) return isNaN(p) - isNaN(q);  // empty cells last
        return p === q ? 0 : (p < q ? -sign : sign);
      }
      return sign * String(x).localeCompare(String(y), undefined, {numeric: true});
    };
  }

  function render() {
    var shown = data.rows.filter(matches);
    if (state.sort) shown.sort(compare(keys.indexOf(state.sort)));
    var fragment = document.createDocumentFragment();
    var folds = col("folds_in_image");
    shown.forEach(function (row) {
      var tr = document.createElement("tr");
      if (row[folds] === true) tr.className = "fold-row";
      row.forEach(function (value, index) {
        var td = document.createElement("td");
        td.textContent = show(value, index);
        if (numeric[index]) td.className = "n";
        else if (keys[index] === "where") td.className = "where";
        tr.appendChild(td);
      });
      fragment.appendChild(tr);
    });
    body.replaceChildren(fragment);
    document.getElementById("entries-count").textContent =
      "Showing " + shown.length + " of " + data.rows.length + " entries";
    for (var i = 0; i < headers.length; i++) {
      var sorted = keys[i] === state.sort;
      var order = state.dir === "desc" ? "descending" : "ascending";
      headers[i].setAttribute("aria-sort", sorted ? order : "none");
    }
    table.setAttribute("data-sort", state.sort ? state.sort + " " + state.dir : "");
  }

  function update() {
    state.q = inputs.q.value.trim();
    state.model = inputs.model.value;
    state.status = inputs.status.value;
    state.folds = inputs.folds.checked;
    state.finite = inputs.finite.checked;
    writeHash();
    render();
  }

  Array.prototype.forEach.call(headers, function (th, index) {
    th.addEventListener("click", function () {
      if (state.sort === keys[index]) state.dir = state.dir === "asc" ? "desc" : "asc";
      else { state.sort = keys[index]; state.dir = "asc"; }
      writeHash();
      render();
    });
  });
  inputs.q.addEventListener("input", update);
  ["model", "status", "folds", "finite"].forEach(function (k) {
    inputs[k].addEventListener("change", update);
  });
  window.addEventListener("hashchange", function () { readHash(); render(); });
  readHash();
  render();
})();
"""


def _json_value(value: Any) -> Any:
    if isinstance(value, float):
        if math.isnan(value):
            return None
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return float(f"{value:.6g}")
    return value


def script_json(data: Any) -> str:
    """JSON safe inside a ``<script>`` element: no ``<``, ``>`` or ``&`` left raw."""
    text = json.dumps(data, ensure_ascii=True, separators=(",", ":"), allow_nan=False)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def coefficients_text(record: dict[str, Any]) -> str:
    """ "a=0.01 b=-0.02 c=0" style text of the coefficients a model uses."""
    names = MODEL_COEFFICIENTS.get(record["model"], ())
    return " ".join(f"{n}={record[n]:g}" for n in names if not math.isnan(record[n]))


def entry_rows(audit: Audit) -> list[list[Any]]:
    """The entry table's rows, values as in :data:`ENTRY_COLUMNS`, made column by column."""
    names = ("model", "a", "b", "c", "k1", "k2")
    models = zip(*map(audit.column, names), strict=True)
    columns = {
        "where": [
            f"{file}:{line}"
            for file, line in zip(audit.column("file"), audit.column("line"), strict=True)
        ],
        "coefficients": [coefficients_text(dict(zip(names, m, strict=True))) for m in models],
    }
    made = []
    for key, _, _ in ENTRY_COLUMNS:
        values = columns[key] if key in columns else audit.column(key)
        made.append(list(map(_json_value, values)) if key in _FLOAT_KEYS else values)
    return list(map(list, zip(*made, strict=True)))


#: The entry table's columns that hold floats.
_FLOAT_KEYS = frozenset(
    ("focal", "crop_factor", "aspect_ratio", "r_max", "d_max", "r_normalized", "r_normalized_paper")
)


def _number(value: float, digits: int = 4) -> str:
    if math.isnan(value):
        return "-"
    if math.isinf(value):
        return "\u221e" if value > 0 else "-\u221e"
    return f"{value:.{digits}g}"


def _table(
    caption: str, header: tuple[str, ...], rows: list[tuple[Any, ...]], table_id: str
) -> str:
    head = "".join(
        f'<th{" class=n" if i else ""} scope="col">{escape(h)}</th>' for i, h in enumerate(header)
    )
    body = []
    for row in rows:
        cells = []
        for i, value in enumerate(row):
            text = f"{value}%" if header[i].startswith("%") and value != "" else str(value)
            cells.append(f"<td{' class=n' if i else ''}>{escape(text)}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return (
        f'<table id="{table_id}"><caption>{escape(caption)}</caption><thead><tr>{head}'
        f"</tr></thead><tbody>{''.join(body)}</tbody></table>"
    )


def _provenance(provenance: Provenance) -> str:
    items = "".join(
        f"<dt>{escape(label)}</dt><dd>{escape(value)}</dd>" for label, value in provenance.items()
    )
    return f'<dl class="provenance" id="provenance">{items}</dl>'


def _folding(audit: Audit) -> str:
    summary = audit.summary
    if not summary.folding:
        return (
            '<p id="folding-none">No entry folds inside its own image: for every '
            "finite r_max, D(r_max) reaches beyond the image corner.</p>"
        )
    m = audit.metrics
    cards = []
    for index in summary.folding:
        entry = audit.entries[index]
        curve = curves.sketch_sample(
            entry, float(m.r_max[index]), float(m.d_max[index]), float(m.r_corner[index])
        )
        record = {
            "model": entry.model,
            **{n: getattr(entry, n) for n in ("a", "b", "c", "k1", "k2")},
        }
        facts = [
            ("where", f"{entry.file}:{entry.line}"),
            ("maker", entry.maker),
            ("type", entry.type),
            (
                "focal",
                f"{entry.focal:g} mm, crop {entry.crop_factor:g}, aspect {entry.aspect_ratio:.4g}",
            ),
            ("model", f"{entry.model}: {coefficients_text(record)}"),
            ("r_max", _number(float(m.r_max[index]))),
            ("D(r_max)", _number(float(m.d_max[index]))),
            ("image corner", _number(float(m.r_corner[index]))),
            ("r_normalized", _number(float(m.r_normalized[index]), 3)),
            ("paper's units", _number(float(m.r_normalized_paper[index]), 3)),
        ]
        details = "".join(
            f"<dt>{escape(k)}</dt><dd{' class=where' if k == 'where' else ''}>{escape(v)}</dd>"
            for k, v in facts
        )
        cards.append(
            f'<article class="fold" data-where="{escape(entry.file)}:{entry.line}">'
            f"<h3>{escape(entry.lens)} at {entry.focal:g} mm</h3>"
            f"{curves.sketch_svg(curve)}<dl>{details}</dl></article>"
        )
    return '<div class="folds" id="folding">' + "".join(cards) + "</div>"


def _not_audited(audit: Audit) -> str:
    statuses = {k: v for k, v in audit.summary.statuses.items() if k != "ok"}
    if not statuses:
        return "<p>Every distortion entry was audited.</p>"
    counts = ", ".join(f"{n} {escape(s)}" for s, n in statuses.items())
    return (
        f"<p>Not audited: {sum(statuses.values())} entries ({counts}). They are in the "
        f"entry table below with their status (filter by status).</p>"
    )


def _comparison(comparison: Comparison) -> str:
    blocks = []
    for title, header, rows in (
        ("Table 1", ("model", "finite", "infinite", "%finite", "total"), comparison.table1),
        ("Table 2", ("model", "positive", "negative", "%negative", "total"), comparison.table2),
    ):
        body = "".join(
            "<tr><td>"
            + escape(name)
            + "</td>"
            + "".join(f"<td class=n>{escape(p)} | {escape(h)}</td>" for p, h in cells)
            + "</tr>"
            for name, cells in rows
        )
        head = "".join(
            f"<th{' class=n' if i else ''}>{escape(h)}</th>" for i, h in enumerate(header)
        )
        blocks.append(
            f'<div class="scroll"><table><caption>{title}: paper | lensaudit</caption>'
            f"<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>"
        )
    other = "".join(
        f"<tr><td>{escape(q)}</td><td class=n>{escape(p)}</td><td>{escape(h)}</td></tr>"
        for q, p, h in comparison.other
    )
    blocks.append(
        '<div class="scroll"><table><caption>Other values</caption><thead><tr>'
        f"<th>quantity</th><th class=n>paper</th><th>lensaudit</th></tr></thead>"
        f"<tbody>{other}</tbody></table></div>"
    )
    differences = "".join(f"<li>{escape(line)}</li>" for line in comparison.differences)
    agreements = "".join(f"<li>{escape(line)}</li>" for line in comparison.agreements)
    blocks.append(
        f'<h3>Differences, one line each</h3><ul id="differences">'
        f"{differences or '<li>none</li>'}</ul>"
    )
    blocks.append(f"<h3>Agreements</h3><ul>{agreements}</ul>")
    return "".join(blocks)


def _options(values: list[str]) -> str:
    return "".join(f'<option value="{escape(v)}">{escape(v)}</option>' for v in values)


def inline_svg(svg: str, prefix: str) -> str:
    """An SVG document (as :func:`lensaudit.report.figures.svg_text` gives it) as
    an ``<svg>`` element for embedding in HTML.

    The XML prolog and namespace declarations are dropped (HTML parsers know
    SVG) and every id is prefixed, so that several figures in one page cannot
    share an id.
    """
    text = svg[svg.index("<svg") :]
    text = re.sub(r'\s+xmlns(:\w+)?="[^"]*"', "", text, count=2)
    ids = set(re.findall(r'\sid="([^"]+)"', text))

    def rename(match: re.Match[str]) -> str:
        name = match.group(2)
        return f"{match.group(1)}{prefix}-{name}" if name in ids else match.group(0)

    text = re.sub(r'(\sid="|#)([\w.\-]+)', rename, text)
    return text.strip()


def render(
    audit: Audit,
    provenance: Provenance,
    histogram: Histogram,
    figure5_svg: str,
    table1: list[tuple[Any, ...]],
    table2: list[tuple[Any, ...]],
    comparison: Comparison | None = None,
    calibrations_html: str = "",
) -> str:
    """The whole page as a string; ``figure5_svg`` is Figure 5 as :func:`inline_svg`
    gives it, ``calibrations_html`` the vignetting and TCA section (see
    :mod:`lensaudit.report.calibrations`), placed after the folds."""
    before, after = render_around_figure5(
        audit, provenance, histogram, table1, table2, comparison, calibrations_html
    )
    return before + figure5_svg + after


def render_around_figure5(
    audit: Audit,
    provenance: Provenance,
    histogram: Histogram,
    table1: list[tuple[Any, ...]],
    table2: list[tuple[Any, ...]],
    comparison: Comparison | None = None,
    calibrations_html: str = "",
) -> tuple[str, str]:
    """The page of :func:`render` before and after Figure 5's ``<svg>``, so that
    the page is made while the figure is drawn."""
    summary = audit.summary
    rows = entry_rows(audit)
    data = script_json({"columns": [list(c) for c in ENTRY_COLUMNS], "rows": rows})
    comparison_html = ""
    if comparison is not None:
        comparison_html = (
            '<section id="paper"><h2>The paper reproduced</h2>'
            + _comparison(comparison)
            + "</section>"
        )
    before = f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="{_content_security_policy()}">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="lensaudit {escape(__version__)}">
<title>lensaudit report: {escape(provenance.database)}</title>
<style>{_CSS}</style>
</head>
<body>
<main>
<h1>lensaudit report</h1>
<p id="headline">{escape(_headline(audit))}</p>
<p class="note">A polynomial distortion D(r) = r F(r) is invertible only up to its first local
maximum r_max. Radii are in Hugin units: 1 is half the short side of the calibration image,
the image corner is at hypot(aspect, 1), and a circular fisheye's image circle at 1 (the circle
inscribed in the short side). An entry folds inside its image when
r_normalized = D(r_max) / corner (or circle) &lt; 1.</p>
<section id="provenance-section"><h2>Provenance</h2>{_provenance(provenance)}</section>
<section id="tables"><h2>Tables 1 and 2</h2>
{_table(TABLE1_CAPTION, TABLE1_HEADER, table1, "table1")}
{_table(TABLE2_CAPTION, TABLE2_HEADER, table2, "table2")}
</section>
<section id="figure5"><h2>Figure 5: r_normalized</h2>
<div class="figure">"""
    after = f"""</div>
<p class="note">Finite r_normalized of the {histogram.entries} rectilinear entries with a finite
r_max. Left: D(r_max) over the image corner, both in Hugin units ({histogram.below_one} below 1).
Right: the paper's Eq. 29, which divides by a corner in focal-length units
({histogram.below_one_paper} below 1).</p>
</section>
<section id="folding-section"><h2>Entries that fold inside their image ({len(summary.folding)})</h2>
<p class="note">Each sketch shows D(r) (black), r_max (red) and the image corner (dashed blue):
the model folds inside the image when its peak stays below the corner.</p>
{_folding(audit)}
</section>
{calibrations_html}
{comparison_html}
{_all_entries(audit)}
</main>
<script id="entries-data" type="application/json">{data}</script>
<script>{_SCRIPT}</script>
</body>
</html>
"""
    return before, after


def _content_security_policy() -> str:
    """The page's policy: its own script (by hash) and inline style; nothing loaded."""
    script_hash = base64.b64encode(hashlib.sha256(_SCRIPT.encode()).digest()).decode()
    return (
        f"default-src 'none'; script-src 'sha256-{script_hash}'; "
        f"style-src 'unsafe-inline'; img-src data:; base-uri 'none'; form-action 'none'"
    )


def _headline(audit: Audit) -> str:
    """One sentence: entries, files, how many were audited, finite and folding."""
    summary = audit.summary
    total = summary.total
    folding_rect = summary.folding_rectilinear
    return (
        f"{summary.entries} distortion entries in {summary.files} files; "
        f"{summary.audited} audited, {total.finite} with a finite r_max "
        f"({total.percent_finite:.2f}%), {len(summary.folding)} folding inside "
        f"their own image ({folding_rect} of them rectilinear)."
    )


def _all_entries(audit: Audit) -> str:
    """The section of every entry: filters over an empty table the page's script fills."""
    models = sorted({e.model for e in audit.entries if e.model})
    statuses = list(audit.summary.statuses)
    heads = "".join(
        f'<th scope="col"{" class=n" if kind == "num" else ""} '
        f'data-key="{key}" aria-sort="none">{escape(title)}</th>'
        for key, title, kind in ENTRY_COLUMNS
    )
    return f"""<section id="all-entries"><h2>All entries</h2>
{_not_audited(audit)}
<div class="controls">
<label>Search <input id="filter-text" type="search" placeholder="maker, lens, file"></label>
<label>Model <select id="filter-model"><option value="">all</option>
{_options(models)}</select></label>
<label>Status <select id="filter-status"><option value="">all</option>
{_options(statuses)}</select></label>
<label><input id="filter-folds" type="checkbox"> folds in image</label>
<label><input id="filter-finite" type="checkbox"> finite r_max</label>
<span id="entries-count" aria-live="polite"></span>
</div>
<noscript><p>Sorting and filtering need JavaScript; every entry is also in entries.csv.
</p></noscript>
<div class="entries-box">
<table id="entries"><thead><tr>{heads}</tr></thead><tbody></tbody></table>
</div>
</section>"""
