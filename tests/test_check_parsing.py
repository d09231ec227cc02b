"""`lensaudit check`'s parsing stage: files parsed in worker processes give what
parsing them here gives, and duplicate lenses are compared on their files
parsed again."""

from __future__ import annotations

from pathlib import Path

from lensaudit import workers
from lensaudit.check import check, parsing, sources_from_paths


def summary(parsed: parsing.ParsedSource) -> tuple:
    """Everything a parsed file holds, as comparable text."""
    columns = {
        kind: [repr(records.column(name)) for name in ("file", "line", "lens", "focal", "status")]
        for kind, records in parsed.calibrations.items()
    }
    return (
        parsed.source.display,
        list(map(repr, parsed.entries)),
        repr(parsed.problem),
        parsed.problem_text,
        parsed.lens_of_entry,
        [
            (lens.line, lens.maker, lens.model, lens.crop_factor, lens.index)
            for lens in parsed.lenses
        ],
        columns,
    )


def test_workers_parse_the_bundled_database_as_this_process_does(bundled_db, monkeypatch):
    sources = sources_from_paths([bundled_db])
    forked = []
    real_fork = workers.os.fork

    def counting_fork() -> int:
        forked.append(1)
        return real_fork()

    monkeypatch.setattr(workers.os, "fork", counting_fork)
    in_workers = parsing.parse_sources(sources)
    here = [parsing.parse_source(source) for source in sources]
    assert list(map(summary, in_workers)) == list(map(summary, here))
    assert len(here) == len(sources) > 50
    # Where workers can run, they did.
    assert forked or workers._cpus() < 2 or not workers._can_fork()


def test_a_broken_and_a_foreign_file_parse_in_workers_as_here(tmp_path, bundled_db):
    for name in ("contax.xml", "slr-tokina.xml"):
        (tmp_path / name).write_bytes((bundled_db / name).read_bytes())
    whole = (bundled_db / "slr-tokina.xml").read_bytes()
    (tmp_path / "broken.xml").write_bytes(whole[: len(whole) // 2])
    (tmp_path / "foreign.xml").write_bytes(b"<html><distortion model='poly3' focal='1'/></html>")
    sources = sources_from_paths([tmp_path])
    in_workers = parsing.parse_sources(sources)
    here = [parsing.parse_source(source) for source in sources]
    assert list(map(summary, in_workers)) == list(map(summary, here))
    assert [p.problem.code if p.problem else "" for p in here] == [
        "xml-error",
        "",
        "not-a-database",
        "",
    ]


LENS = """<lens>
        <maker>Test</maker>
        <model>{model}</model>
        <mount>M</mount>
        <cropfactor>1.5</cropfactor>
        <calibration><distortion model="poly3" focal="10" k1="{k1}"/></calibration>
    </lens>"""


def database(*lenses: str, namespace: str = "") -> bytes:
    return f"<lensdatabase{namespace}>\n{chr(10).join(lenses)}\n</lensdatabase>\n".encode()


def duplicate_severities(path: Path) -> list[tuple[str, int]]:
    return [(f.severity, f.line) for f in check(path).findings if f.code == "duplicate-lens"]


def test_a_lens_defined_twice_alike_is_a_warning_at_the_second(tmp_path):
    path = tmp_path / "a.xml"
    path.write_bytes(
        database(LENS.format(model="L", k1="0.01"), LENS.format(model="l ", k1="0.01"))
    )
    assert duplicate_severities(path) == [("warning", 9)]


def test_a_lens_defined_twice_differently_is_an_error(tmp_path):
    path = tmp_path / "a.xml"
    path.write_bytes(database(LENS.format(model="L", k1="0.01"), LENS.format(model="L", k1="0.02")))
    assert duplicate_severities(path) == [("error", 9)]


def test_lenses_in_a_default_namespace_compare_as_without_it(tmp_path):
    path = tmp_path / "a.xml"
    lenses = (LENS.format(model="L", k1="0.01"), LENS.format(model="L", k1="0.01"))
    path.write_bytes(database(*lenses, namespace=' xmlns="http://example.com/lensfun"'))
    assert duplicate_severities(path) == [("warning", 9)]


def test_duplicates_in_two_files_are_compared_on_each_file(tmp_path):
    (tmp_path / "a.xml").write_bytes(database(LENS.format(model="L", k1="0.01")))
    (tmp_path / "b.xml").write_bytes(database("\n\n" + LENS.format(model="L", k1="0.03")))
    found = [(f.severity, Path(f.file).name, f.line) for f in check(tmp_path).findings]
    assert ("error", "b.xml", 4) in found
