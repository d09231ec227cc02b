"""report.html in a real browser: headless Chromium runs the page's script, offline.

The page is opened from a file:// URL with a view state in its fragment
(filter, sort); the DOM Chromium dumps after the script ran is what a user
sees. Skipped where no Chromium is installed (`apt-get install chromium`).
"""

from __future__ import annotations

import base64
import csv
import hashlib
import json
import re
import shutil
import subprocess
from urllib.parse import quote

import pytest
from lxml import html as lxml_html

from lensaudit.report import audit, paper, write_report

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
BROWSER = next((shutil.which(name) for name in BROWSERS if shutil.which(name)), None)

pytestmark = pytest.mark.skipif(
    BROWSER is None, reason="no Chromium found (install it with `apt-get install chromium`)"
)

HOSTILE_LENS = "<img src=x onerror=\"document.body.setAttribute('data-pwned','1')\">"


def rendered(page, fragment, profile, window="1400,900"):
    """The DOM of ``page`` after its script ran, as an lxml tree."""
    url = page.resolve().as_uri() + ("#" + fragment if fragment else "")
    result = subprocess.run(
        [
            BROWSER,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--no-default-browser-check",
            f"--user-data-dir={profile}",
            f"--window-size={window}",
            "--virtual-time-budget=5000",
            "--dump-dom",
            url,
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    return lxml_html.fromstring(result.stdout)


def table_rows(dom):
    header = [th.text_content().strip() for th in dom.xpath('//table[@id="entries"]/thead//th')]
    return [
        dict(zip(header, (td.text_content() for td in tr.xpath("./td")), strict=True))
        for tr in dom.xpath('//table[@id="entries"]/tbody/tr')
    ]


@pytest.fixture(scope="module")
def bundled(bundled_db, tmp_path_factory):
    """The report of the bundled database, with the paper comparison (the widest page)."""
    out = tmp_path_factory.mktemp("bundled")
    write_report(audit(bundled_db), out, paper_values=paper.load_values())
    with (out / "entries.csv").open(newline="") as stream:
        entries = list(csv.DictReader(stream))
    return out / "report.html", entries


@pytest.fixture(scope="module")
def profile(tmp_path_factory):
    return tmp_path_factory.mktemp("chromium-profile")


@pytest.fixture(scope="module")
def full_view(bundled, profile):
    """The page as opened, no fragment: every entry shown."""
    return rendered(bundled[0], "", profile)


def test_the_script_builds_the_full_table(bundled, full_view):
    _, entries = bundled
    dom = full_view
    rows = table_rows(dom)
    assert len(rows) == len(entries)
    assert dom.xpath('string(//*[@id="entries-count"])') == (
        f"Showing {len(entries)} of {len(entries)} entries"
    )
    assert [r["file:line"] for r in rows[:3]] == [f"{e['file']}:{e['line']}" for e in entries[:3]]


def test_a_filter_in_the_url_shows_only_matching_entries(bundled, profile):
    page, entries = bundled
    dom = rendered(page, "q=" + quote("tokina 11-16") + "&model=ptlens", profile)
    expected = [
        f"{e['file']}:{e['line']}"
        for e in entries
        if "tokina" in (e["maker"] + " " + e["lens"]).lower()
        and "11-16" in e["lens"]
        and e["model"] == "ptlens"
    ]
    assert 3 <= len(expected) < 50
    assert [r["file:line"] for r in table_rows(dom)] == expected
    assert dom.xpath('string(//*[@id="entries-count"])').startswith(f"Showing {len(expected)} of")
    assert dom.xpath('//input[@id="filter-text"]/@value') in ([], ["tokina 11-16"])


def test_sorting_by_a_column_orders_the_rows_numerically(bundled, profile):
    page, entries = bundled
    dom = rendered(page, "folds=1&sort=r_normalized&dir=desc", profile)
    folding = [e for e in entries if e["folds_in_image"] == "true"]
    folding.sort(key=lambda e: float(e["r_normalized"]), reverse=True)
    rows = table_rows(dom)
    assert [r["file:line"] for r in rows] == [f"{e['file']}:{e['line']}" for e in folding]
    values = [float(r["r_normalized"]) for r in rows]
    assert values == sorted(values, reverse=True) and all(v < 1 for v in values)
    header = dom.xpath('//table[@id="entries"]//th[@data-key="r_normalized"]')[0]
    assert header.get("aria-sort") == "descending"


def test_infinite_r_max_sorts_after_finite_and_shows_as_infinity(bundled, profile):
    page, _ = bundled
    rows = table_rows(rendered(page, "q=tokina&sort=r_max", profile))
    shown = [r["r_max"] for r in rows]
    finite = [float(v) for v in shown if v != "\u221e"]
    assert finite == sorted(finite)
    assert "\u221e" in shown and shown.index("\u221e") == len(finite)


def test_hostile_names_stay_text_in_the_browser(write_xml, tmp_path, profile):
    name = HOSTILE_LENS.replace("&", "&amp;").replace("<", "&lt;").replace('"', "&quot;")
    path = write_xml(f"""<lensdatabase version="2"><lens><maker>Evil</maker>
        <model>{name}</model><mount>M</mount><cropfactor>1</cropfactor><calibration>
        <distortion model="poly3" focal="10" k1="-0.3"/></calibration></lens></lensdatabase>""")
    write_report(audit(path.parent), tmp_path / "out")
    dom = rendered(tmp_path / "out" / "report.html", "", profile)
    assert dom.xpath("//body/@data-pwned") == []
    assert not dom.xpath("//img")
    assert table_rows(dom)[0]["lens"] == HOSTILE_LENS
    assert dom.xpath('//article[@class="fold"]/h3')[0].text_content().startswith(HOSTILE_LENS)


def test_the_page_shows_provenance_tables_and_figure(bundled, full_view):
    _, entries = bundled
    dom = full_view
    assert dom.xpath('//dl[@id="provenance"]/dt[.="Content hash (SHA-256)"]')
    assert re.search(r"Total\s*\d+", dom.xpath('string(//table[@id="table1"])'))
    assert dom.xpath('//section[@id="figure5"]//svg')
    assert len(dom.xpath('//article[@class="fold"]')) == sum(
        e["folds_in_image"] == "true" for e in entries
    )


# Measures the laid-out page once its own script has run, and writes what it
# found into the DOM for --dump-dom. It is allowed by adding its hash to the
# page's Content-Security-Policy; nothing else of the page changes.
PROBE = r"""
window.addEventListener("load", function () {
  var root = document.documentElement;
  var found = {scrollWidth: root.scrollWidth, clientWidth: root.clientWidth, sketches: []};
  var box = document.getElementById("entries").parentElement;
  found.tableBox = {scrollWidth: box.scrollWidth, clientWidth: box.clientWidth,
                    right: box.getBoundingClientRect().right};
  document.querySelectorAll("article.fold svg").forEach(function (svg) {
    var view = svg.viewBox.baseVal, outside = [], drawn = 0;
    var shown = svg.getBoundingClientRect(), scale = shown.width / view.width, fonts = [];
    svg.querySelectorAll("*").forEach(function (element) {
      var b = element.getBBox();
      drawn += 1;
      if (b.x < view.x - 0.5 || b.y < view.y - 0.5 ||
          b.x + b.width > view.x + view.width + 0.5 ||
          b.y + b.height > view.y + view.height + 0.5) {
        outside.push(element.tagName + " " + element.textContent);
      }
      if (element.tagName === "text") {
        fonts.push(parseFloat(getComputedStyle(element).fontSize) * scale);
      }
    });
    found.sketches.push({where: svg.closest("article").dataset.where, drawn: drawn,
                         outside: outside, width: shown.width, height: shown.height,
                         smallestFont: Math.min.apply(null, fonts)});
  });
  // Every cell that holds a file:line: on how many lines its text is laid out.
  found.where = {checked: 0, wrapped: []};
  document.querySelectorAll("td, dd").forEach(function (cell) {
    if (!/^[^\s:]+\.xml:\d+$/.test(cell.textContent)) return;
    var range = document.createRange(), tops = {};
    range.selectNodeContents(cell);
    Array.prototype.forEach.call(range.getClientRects(), function (rect) {
      if (rect.width > 0) tops[Math.round(rect.top)] = true;
    });
    found.where.checked += 1;
    if (Object.keys(tops).length !== 1) found.where.wrapped.push(cell.textContent);
  });
  var out = document.createElement("pre");
  out.id = "probe";
  out.textContent = JSON.stringify(found);
  document.body.appendChild(out);
});
"""


def probed(page, tmp_path, profile, window):
    """What :data:`PROBE` measured on ``page`` in a ``window`` (WIDTH,HEIGHT) browser."""
    text = page.read_text(encoding="utf-8")
    digest = base64.b64encode(hashlib.sha256(PROBE.encode()).digest()).decode()
    text, allowed = re.subn(
        r"script-src ('sha256-[^']+')", rf"script-src \1 'sha256-{digest}'", text
    )
    assert allowed == 1
    copy = tmp_path / page.name
    copy.write_text(text.replace("</body>", f"<script>{PROBE}</script></body>"), "utf-8")
    dom = rendered(copy, "", profile, window)
    return json.loads(dom.xpath('string(//pre[@id="probe"])'))


@pytest.fixture(scope="module")
def measured_at_1400(bundled, profile, tmp_path_factory):
    return probed(bundled[0], tmp_path_factory.mktemp("probe"), profile, "1400,900")


@pytest.fixture(scope="module")
def measured_at_800(bundled, profile, tmp_path_factory):
    return probed(bundled[0], tmp_path_factory.mktemp("probe"), profile, "800,900")


@pytest.fixture(params=["1400", "800"])
def measured(request):
    """The page measured in a 1400 px and in an 800 px wide window."""
    return request.getfixturevalue(f"measured_at_{request.param}")


def test_the_page_does_not_scroll_sideways_in_a_1400_px_window(measured_at_1400):
    found = measured_at_1400
    assert 1300 <= found["clientWidth"] <= 1400
    assert found["scrollWidth"] <= found["clientWidth"]
    assert found["tableBox"]["right"] <= found["clientWidth"]


def test_the_whole_entry_table_fits_its_box_in_a_1400_px_window(measured_at_1400):
    box = measured_at_1400["tableBox"]
    assert box["scrollWidth"] <= box["clientWidth"]


def test_the_entry_table_scrolls_in_its_own_box_in_a_narrow_window(measured_at_800):
    found = measured_at_800
    assert found["scrollWidth"] <= found["clientWidth"]
    assert found["tableBox"]["scrollWidth"] > found["tableBox"]["clientWidth"]


def test_every_sketch_is_drawn_inside_its_view_box(bundled, measured_at_1400):
    _, entries = bundled
    folding = [f"{e['file']}:{e['line']}" for e in entries if e["folds_in_image"] == "true"]
    sketches = measured_at_1400["sketches"]
    assert sorted(s["where"] for s in sketches) == sorted(folding)
    assert all(s["drawn"] >= 8 for s in sketches)
    assert {s["where"]: s["outside"] for s in sketches} == {w: [] for w in folding}


def test_no_file_line_breaks_across_lines(bundled, measured):
    # "slr-tokina.xml:17" may break after its hyphen; it must not, in the entry
    # table, the folding cards or the vignetting table, however narrow the window.
    _, entries = bundled
    folding = sum(e["folds_in_image"] == "true" for e in entries)
    assert measured["where"]["checked"] >= len(entries) + folding
    assert measured["where"]["wrapped"] == []


def test_fold_sketches_are_large_with_readable_labels(measured):
    sketches = measured["sketches"]
    assert sketches
    for sketch in sketches:
        assert sketch["width"] >= 400 and sketch["height"] >= 240, sketch["where"]
        # Axis and value labels at least 12 CSS pixels high, as drawn.
        assert sketch["smallestFont"] >= 12, sketch["where"]
