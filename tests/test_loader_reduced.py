"""The distortion audit parses a file with a placeholder for each <vignetting/>
element Lensfun writes (loader._distortion_file), and no other check; what it
reads, and what it finds wrong, must be what the whole tree gives.

The reference is the same loader with the whole file parsed
(loader.parse_file), on real files, on every file version of Lensfun's
history at revisions spread over it, and on real files mutated by
hypothesis, with mutations aimed at the placeholders: comments, attribute
values, processing instructions, CDATA, document types, namespaces and
encodings around the elements they replace, and text outside the root.
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


def test_placeholders_replace_calibration_elements_and_keep_every_line(bundled_db):
    data = (bundled_db / "slr-canon.xml").read_bytes()
    replaced = loader._CALIBRATION_ELEMENT.sub(loader._PLACEHOLDER, data)
    assert b"<vignetting" not in replaced and replaced.count(b"<tca") < data.count(b"<tca") / 10
    assert replaced.count(b"\n") == data.count(b"\n") and len(replaced) < len(data) / 2


def test_file_versions_across_lensfuns_history_read_as_the_whole_tree(tmp_path):
    versions = file_versions(tmp_path)
    for data in versions:
        assert_reads_as_whole(data)
    assert len(versions) > 100


#: A <vignetting/> element as Lensfun writes it: what a placeholder replaces.
VIGNETTING = (
    b'<vignetting model="pa" focal="10" aperture="2.8" distance="10" k1="-0.1" k2="1e-05" k3="0"/>'
)

#: A <tca/> element as Lensfun writes it.
TCA = b'<tca model="poly3" focal="10" br="-1e-05" vr="1.0001" bb="0" vb="0.9999"/>'

#: Text that changes what a placeholder may replace, or how the file must be read.
SNIPPETS = [
    VIGNETTING,
    TCA,
    b"<!-- " + TCA + b" -- -->",
    b"<x a='" + TCA + b"'/>",
    TCA.replace(b'"0"', b'"--0"'),
    TCA.replace(b' vb="0.9999"', b' vb="0.9999" vr="1"'),
    b"<!-- " + VIGNETTING + b" -->",
    b"<!-- -- " + VIGNETTING + b" -->",
    b"<!--" + VIGNETTING + b"-->",
    b"<!---" + VIGNETTING + b"--->",
    b"<x a='" + VIGNETTING + b"'/>",
    b"<x a='" + VIGNETTING + b"'>",
    b"<?pi " + VIGNETTING + b" ?>",
    b"<?pi " + VIGNETTING + b"?>",
    VIGNETTING.replace(b' k3="0"', b' k3="0" k3="1"'),
    VIGNETTING.replace(b' k3="0"', b' k3="0"\x0c'),
    VIGNETTING.replace(b'"10"', b'"1\xff0"', 1),
    VIGNETTING + VIGNETTING,
    b"<lens>" + VIGNETTING + b"</lens>",
    b"</lensdatabase>" + VIGNETTING,
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


#: Around an element: a comment (with dashes that break it or not), an attribute
#: value, a tag, a processing instruction, a CDATA section.
WRAPPERS = [
    (b"<!-- ", b" -->"),
    (b"<!-- -", b"- -->"),
    (b"<!--", b""),
    (b"<!-- -- ", b" -->"),
    (b"<x a='", b"'/>"),
    (b'<x a="', b'"/>'),
    (b"<x ", b">"),
    (b"<?pi ", b" ?>"),
    (b"<![CDATA[", b"]]>"),
]


def wrap_element(draw, rng, data: bytes) -> bytes:
    """A calibration element inside something else (see :data:`WRAPPERS`)."""
    found = list(loader._CALIBRATION_ELEMENT.finditer(data))
    if not found:
        return data
    match = rng.choice(found)
    before, after = draw(st.sampled_from(WRAPPERS))
    return data[: match.start()] + before + match.group() + after + data[match.end() :]


@st.composite
def mutated_for_the_cut(draw) -> bytes:
    data = ORIGINAL[draw(st.sampled_from(sorted(ORIGINAL)))]
    rng = random.Random(draw(st.integers(0, 2**32)))
    mutations = (*MUTATIONS, insert_snippet, insert_snippet, wrap_element, wrap_element)
    for _ in range(draw(st.integers(1, 3))):
        data = draw(st.sampled_from(mutations))(draw, rng, data)
    return data


@SETTINGS
@given(mutated_for_the_cut())
def test_mutated_files_read_as_the_whole_tree(data):
    assert_reads_as_whole(data)


@pytest.mark.parametrize("snippet", SNIPPETS)
@pytest.mark.parametrize(
    "where", [b"<maker>Mamiya", b"<calibration>", b"<lensdatabase", b"</lensdatabase>", b""]
)
def test_each_snippet_anywhere_reads_as_the_whole_tree(snippet, where):
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


@pytest.mark.parametrize("before, after", WRAPPERS)
@pytest.mark.parametrize("which", [0, -1])
def test_a_calibration_element_in_any_context_reads_as_the_whole_tree(before, after, which):
    data = ORIGINAL["compact-samsung.xml"]
    match = list(loader._CALIBRATION_ELEMENT.finditer(data))[which]
    wrapped = data[: match.start()] + before + match.group() + after + data[match.end() :]
    assert_reads_as_whole(wrapped)


def test_text_outside_the_root_is_an_error_with_or_without_placeholders():
    data = ORIGINAL["compact-samsung.xml"]
    element = loader._CALIBRATION_ELEMENT.search(data).group()
    for changed in (element + data, data + element):
        rows, error = loader.read_rows(changed)
        assert error and rows[0][-2] == loader.STATUS_XML_ERROR
        assert_reads_as_whole(changed)
