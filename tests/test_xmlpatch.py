"""Byte-preserving attribute patches: found where the reader says, nothing else touched."""

from __future__ import annotations

import os
import stat

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from lxml import etree

from lensaudit import read
from lensaudit.xmlpatch import (
    FilePatch,
    PatchError,
    locate,
    set_attributes,
    start_tags,
    unified_diff,
    write,
)

DOCUMENT = b"""<?xml version="1.0" encoding="UTF-8"?>
<!DOCTYPE lensdatabase [ <!ENTITY note "<distortion a='9'/>"> ]>
<lensdatabase version="2">
    <!-- <distortion model="ptlens" focal="11" a="1" b="2" c="3"/> -->
    <lens>
        <model>Caf\xc3\xa9 10mm</model>
        <calibration>
            <distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>
            <distortion   model='poly3'
                focal = '12'
                k1='-0.01'  />
            <![CDATA[ <distortion model="ptlens" focal="13"/> ]]>
            <?note <distortion model="ptlens" focal="14"/> ?>
            <distortion model="ptlens" focal="15" a="0.001" c="0.002"></distortion>
        </calibration>
    </lens>
</lensdatabase>
"""


def lxml_lines(data: bytes) -> list[int]:
    parser = etree.XMLParser(resolve_entities=False, load_dtd=False, no_network=True)
    return [e.sourceline for e in etree.fromstring(data, parser).iter("distortion")]


def reader_lines(data: bytes) -> list[int]:
    """The line the reader gives each <distortion> of ``data``: the line fix locates."""
    tables = read.read_bytes(data, "test.xml")
    assert tables.status == "ok", tables.error
    return [row[0] for row in tables.distortion]


def test_start_tags_are_numbered_by_the_line_libxml2_reports():
    assert [t.line for t in start_tags(DOCUMENT, "distortion")] == lxml_lines(DOCUMENT)


@pytest.mark.parametrize("line_end", [b"\n", b"\r\n", b"\r"], ids=["LF", "CRLF", "CR"])
def test_start_tags_are_numbered_by_the_line_the_reader_gives(line_end):
    data = DOCUMENT.replace(b"\n", line_end)
    assert [t.line for t in start_tags(data, "distortion")] == reader_lines(data) == [8, 11, 14]


def test_comments_cdata_instructions_and_doctype_are_not_elements():
    assert len(list(start_tags(DOCUMENT, "distortion"))) == 3


def test_raw_attribute_values_are_read_with_their_quotes():
    tag = list(start_tags(DOCUMENT, "distortion"))[1]
    assert tag.values() == {"model": "poly3", "focal": "12", "k1": "-0.01"}
    assert {a.quote for a in tag.attributes.values()} == {"'"}


def test_only_the_changed_value_bytes_change():
    tag = locate(DOCUMENT, "distortion", 8, lambda v: v["focal"] == "11")
    patched = set_attributes(DOCUMENT, [(tag, {"a": "-0.0123", "b": "-0.002"})])
    assert patched == DOCUMENT.replace(b'a="-0.024"', b'a="-0.0123"')


def test_single_quotes_and_odd_spacing_are_kept():
    tag = locate(DOCUMENT, "distortion", 11, lambda v: v["model"] == "poly3")
    patched = set_attributes(DOCUMENT, [(tag, {"k1": "-0.00512"})])
    assert patched == DOCUMENT.replace(b"k1='-0.01'  />", b"k1='-0.00512'  />")


def test_a_missing_attribute_is_added_after_the_last_one():
    tag = locate(DOCUMENT, "distortion", 14, lambda v: True)
    patched = set_attributes(DOCUMENT, [(tag, {"b": "0.0030"})])
    assert patched == DOCUMENT.replace(b'c="0.002">', b'c="0.002" b="0.0030">')


def test_several_elements_of_one_file_are_patched_together():
    tags = list(start_tags(DOCUMENT, "distortion"))
    patched = set_attributes(DOCUMENT, [(tags[2], {"a": "0.5"}), (tags[0], {"c": "0.25"})])
    expected = DOCUMENT.replace(b'c="0.005"', b'c="0.25"').replace(b'a="0.001"', b'a="0.5"')
    assert patched == expected


def test_values_that_would_need_escaping_are_refused():
    tag = list(start_tags(DOCUMENT, "distortion"))[0]
    with pytest.raises(PatchError, match="escaping"):
        set_attributes(DOCUMENT, [(tag, {"a": 'x"y'})])


def test_no_element_on_the_line_is_an_error_naming_the_line():
    with pytest.raises(PatchError, match="line 9: no <distortion>"):
        locate(DOCUMENT, "distortion", 9, lambda v: True)


def test_other_values_on_the_line_are_an_error():
    with pytest.raises(PatchError, match="line 8: .*other attribute values"):
        locate(DOCUMENT, "distortion", 8, lambda v: v["a"] == "-0.025")


def test_a_malformed_start_tag_is_an_error_not_a_guess():
    with pytest.raises(PatchError, match="not well formed"):
        list(start_tags(b"<a><distortion a=1/></a>", "distortion"))


def test_the_diff_shows_the_changed_line(tmp_path):
    tag = locate(DOCUMENT, "distortion", 8, lambda v: True)
    patch = FilePatch(
        tmp_path / "x.xml", "x.xml", DOCUMENT, set_attributes(DOCUMENT, [(tag, {"a": "1"})])
    )
    diff = unified_diff(patch)
    assert diff.startswith("--- a/x.xml\n+++ b/x.xml\n")
    removed = [
        line for line in diff.splitlines() if line.startswith("-") and not line.startswith("---")
    ]
    added = [
        line for line in diff.splitlines() if line.startswith("+") and not line.startswith("+++")
    ]
    assert len(removed) == len(added) == 1
    assert 'a="1"' in added[0] and 'a="-0.024"' in removed[0]


def test_write_replaces_the_file_and_keeps_its_permissions(tmp_path):
    path = tmp_path / "x.xml"
    path.write_bytes(DOCUMENT)
    os.chmod(path, 0o640)
    patched = DOCUMENT.replace(b'a="-0.024"', b'a="-0.02"')
    write(FilePatch(path, "x.xml", DOCUMENT, patched))
    assert path.read_bytes() == patched
    assert stat.S_IMODE(path.stat().st_mode) == 0o640
    assert [p.name for p in tmp_path.iterdir()] == ["x.xml"]  # no temporary file left


def test_write_refuses_a_file_that_changed_since_it_was_read(tmp_path):
    path = tmp_path / "x.xml"
    path.write_bytes(DOCUMENT + b"\n")
    with pytest.raises(PatchError, match="changed since it was read"):
        write(FilePatch(path, "x.xml", DOCUMENT, DOCUMENT.replace(b"-0.024", b"-0.02")))
    assert path.read_bytes() == DOCUMENT + b"\n"


_name = st.sampled_from(["a", "b", "c", "k1", "focal", "model", "x-y"])
_value = st.text(alphabet="0123456789.-e+abc ", max_size=8)
_space = st.text(alphabet=" \t\r\n", min_size=1, max_size=3)


@st.composite
def documents(draw):
    """A database-like document: tags spread over lines, random quotes and spacing."""
    parts = [b"<lensdatabase>\n"]
    for _ in range(draw(st.integers(1, 4))):
        names = draw(st.lists(_name, min_size=1, max_size=4, unique=True))
        tag = b"<distortion"
        for name in names:
            quote = draw(st.sampled_from(['"', "'"]))
            around = draw(st.sampled_from(["", " ", "\n "]))
            tag += (
                draw(_space).encode()
                + f"{name}{around}={around}{quote}{draw(_value)}{quote}".encode()
            )
        tag += draw(st.sampled_from([b"/>", b" />", b"\n/>", b"></distortion>"]))
        filler = draw(st.sampled_from([b"\n", b"\n<!-- <distortion a='1'/> -->\n", b" "]))
        parts += [tag, filler]
    parts.append(b"</lensdatabase>\n")
    return b"".join(parts)


@settings(max_examples=150, deadline=None)
@given(documents(), st.data())
def test_any_patch_changes_exactly_the_chosen_value(data, choices):
    tags = list(start_tags(data, "distortion"))
    assert [t.line for t in tags] == reader_lines(data)
    tag = choices.draw(st.sampled_from(tags))
    name = choices.draw(st.sampled_from(sorted(tag.attributes)))
    new = choices.draw(st.text(alphabet="0123456789.-", min_size=1, max_size=10))
    patched = set_attributes(data, [(tag, {name: new})])
    old = tag.attributes[name]
    assert patched == data[: old.start] + new.encode() + data[old.end :]
    parser = etree.XMLParser(resolve_entities=False, load_dtd=False)
    before = [dict(e.attrib) for e in etree.fromstring(data, parser).iter("distortion")]
    after = [dict(e.attrib) for e in etree.fromstring(patched, parser).iter("distortion")]
    before[tags.index(tag)][name] = new
    assert after == before
