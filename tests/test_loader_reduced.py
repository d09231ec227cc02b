"""The distortion audit parses a file without its <vignetting/> and <tca/> elements
(loader._distortion_file); what it reads must be what the whole tree gives.

The reference is the same loader with the whole file parsed
(loader.parse_file), on real files, on every file version of Lensfun's
history at revisions spread over it, and on real files mutated by
hypothesis, with mutations aimed at the cut: comments, CDATA, document
types, namespaces and encodings around the elements it removes.
"""

from __future__ import annotations

import random

import pytest
from hypothesis import given
from hypothesis import strategies as st

from history_blobs import file_versions
from lensaudit import loader
from test_fuzz_mutations import MUTATIONS, ORIGINAL, SETTINGS


def whole_tree_rows(data: bytes) -> tuple[list, str]:
    """loader.read_rows with every element parsed."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(loader, "_distortion_file", loader.parse_file)
        return loader.read_rows(data)


def assert_reads_as_whole(data: bytes) -> None:
    assert loader.read_rows(data) == whole_tree_rows(data)


def test_every_bundled_file_reads_as_the_whole_tree(bundled_db):
    for path in sorted(bundled_db.glob("*.xml")):
        assert_reads_as_whole(path.read_bytes())


def test_the_cut_leaves_no_calibration_element_and_every_line(bundled_db):
    data = (bundled_db / "slr-canon.xml").read_bytes()
    cut = loader._CALIBRATION_ELEMENT.sub(b"", data)
    assert b"<vignetting" not in cut and b"<tca" not in cut
    assert cut.count(b"\n") == data.count(b"\n") and len(cut) < len(data) / 2


def test_file_versions_across_lensfuns_history_read_as_the_whole_tree(tmp_path):
    versions = file_versions(tmp_path)
    for data in versions:
        assert_reads_as_whole(data)
    assert len(versions) > 100


#: Text that changes what the cut may remove, or how the file must be read.
SNIPPETS = [
    b"<!--",
    b"-->",
    b"-",
    b"--",
    b"<![CDATA[",
    b"]]>",
    b"<!DOCTYPE lensdatabase>",
    b"<!DOCTYPE lensdatabase [<!ENTITY e \"<tca model='poly3' focal='1'/>\">]>",
    b'<tca model="poly3" focal="1"/>',
    b'<vignetting model="pa" focal="1" aperture="2" distance="10"/>',
    b'<tca model="poly3" focal="1" focal="2"/>',
    b'<tca x:y="1"/>',
    b' xmlns="urn:x"',
    b'<?pi <tca model="poly3"/> ?>',
    b'"',
    b"<",
    b">",
    b"\r",
    b"\n",
    b"&#60;",
    b"&amp;",
    b"\xef\xbb\xbf",
    b'<?xml version="1.0" encoding="ISO-8859-1"?>',
    b"\xff",
    b'<distortion model="ptlens" focal="10" a="0.01" b="0" c="0"/>',
]


def insert_snippet(draw, rng, data: bytes) -> bytes:
    """A snippet at a random place, or next to a calibration element."""
    elements = [m.start() for m in loader._CALIBRATION_ELEMENT.finditer(data)]
    position = (
        rng.choice(elements) if elements and rng.random() < 0.6 else rng.randint(0, len(data))
    )
    return data[:position] + draw(st.sampled_from(SNIPPETS)) + data[position:]


def comment_out_element(draw, rng, data: bytes) -> bytes:
    """A calibration element inside a comment, with or without dashes around it."""
    found = list(loader._CALIBRATION_ELEMENT.finditer(data))
    if not found:
        return data
    match = rng.choice(found)
    before, after = draw(
        st.sampled_from([(b"<!-- ", b" -->"), (b"<!-- -", b"- -->"), (b"<!--", b"")])
    )
    return data[: match.start()] + before + match.group() + after + data[match.end() :]


@st.composite
def mutated_for_the_cut(draw) -> bytes:
    data = ORIGINAL[draw(st.sampled_from(sorted(ORIGINAL)))]
    rng = random.Random(draw(st.integers(0, 2**32)))
    mutations = (*MUTATIONS, insert_snippet, insert_snippet, comment_out_element)
    for _ in range(draw(st.integers(1, 3))):
        data = draw(st.sampled_from(mutations))(draw, rng, data)
    return data


@SETTINGS
@given(mutated_for_the_cut())
def test_mutated_files_read_as_the_whole_tree(data):
    assert_reads_as_whole(data)


@pytest.mark.parametrize("snippet", SNIPPETS)
@pytest.mark.parametrize("where", [b"<maker>Mamiya", b"<calibration>", b"<lensdatabase"])
def test_each_snippet_in_a_lens_reads_as_the_whole_tree(snippet, where):
    data = ORIGINAL["6x6.xml"]
    position = data.index(where) + len(where)
    assert_reads_as_whole(data[:position] + snippet + data[position:])


def test_an_element_with_an_undeclared_prefix_is_not_cut():
    # libxml2 checks namespace prefixes only as it builds a tree: left in, the
    # file is an XML error, as the whole tree says.
    data = ORIGINAL["6x6.xml"].replace(
        b"<maker>Mamiya</maker>", b'<maker>M<tca x:y="1"/></maker>', 1
    )
    rows, error = loader.read_rows(data)
    assert "not defined" in error and rows[0][-2] == loader.STATUS_XML_ERROR
    assert_reads_as_whole(data)
