"""The reader's memo of lenses (read.Pieces) and the solver's memo of entries
give, bit for bit, what reading and solving each file from scratch gives: on
real file versions of every era, and on documents built to mislead them."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from history_blobs import file_versions, read_alone
from lensaudit import read
from lensaudit.pipeline import metric_columns, row_columns
from lensaudit.read.records import FileTables


def tables_text(tables: FileTables) -> str:
    """Everything read of a file, as text (NaN equal to NaN, 0.0 apart from -0.0),
    where liblensfun stops reading it included."""
    assert "refusal" in FileTables.STORED
    values = [getattr(tables, name) for name in FileTables.STORED] + [tables.refusal_judged]
    values += [tables.vignetting, tables.tca, tables.lens_of_vignetting, tables.lens_of_tca]
    return repr(values)


def read_both(
    contents: list[bytes], calibrations: bool = False, refusals: bool = True
) -> tuple[list[str], list[str]]:
    """Each content read alone, and all of them read in turn with one memo."""
    pieces = read.Pieces()
    options = {"calibrations": calibrations, "refusals": refusals}
    alone = [tables_text(tables) for tables in read_alone(contents, **options)]
    with_memo = [
        tables_text(read.read_bytes(d, "f.xml", pieces=pieces, **options)) for d in contents
    ]
    return alone, with_memo


def test_real_file_versions_read_with_the_memo_as_alone(tmp_path):
    versions = file_versions(tmp_path, revisions=40)
    alone, with_memo = read_both(versions)
    assert len(versions) > 200
    assert with_memo == alone
    alone, with_memo = read_both(versions[:150], calibrations=True)
    assert with_memo == alone
    alone, with_memo = read_both(versions[:150], refusals=False)  # as scan and history read
    assert with_memo == alone


def pieces_as_whole(contents: list[bytes]) -> tuple[int, list[str]]:
    """How many contents read_pieces reads, and where what it reads differs
    from read_bytes: its pieces' rows one after the other, each at its line."""
    pieces, by_pieces = read.Pieces(), 0
    wrong = []
    for number, (data, whole) in enumerate(zip(contents, read_alone(contents), strict=True)):
        by_piece = read.read_pieces(data, pieces)
        if by_piece is None:
            read.read_bytes(data, "f.xml", pieces=pieces)  # learns the pieces as history does
            continue
        by_pieces += 1
        rows = [row[1:] for rows in by_piece for row in rows]
        # As text: NaN equal to NaN, 0.0 apart from -0.0 (see tables_text).
        if whole.status != "ok" or repr(rows) != repr([row[1:] for row in whole.distortion]):
            wrong.append(f"content {number}")
    return by_pieces, wrong


def test_real_file_versions_read_by_piece_as_whole(tmp_path):
    versions = file_versions(tmp_path, revisions=40)
    by_pieces, wrong = pieces_as_whole(versions)
    assert wrong == []
    assert by_pieces > 0.8 * len(versions)  # nearly all are read so


def test_real_file_versions_read_one_after_another_as_alone(tmp_path):
    # Each version after the one before it, as the history reads them: most of
    # what the memo found in the last document is taken as it is.
    versions = file_versions(tmp_path, revisions=60, by_file=True)
    alone, with_memo = read_both(versions, refusals=False)
    assert with_memo == alone
    by_pieces, wrong = pieces_as_whole(versions)
    assert wrong == [] and by_pieces > 0.8 * len(versions)


def test_what_the_last_document_gave_is_taken_only_where_it_is_found_again():
    # The lens is not closed in the first document: its pieces are guessed from
    # inside it (the mount). The second closes it after the first's mount ends.
    lens = LENS.replace("</lens>\n", "")
    first = document(OTHER, lens, MOUNT)
    second = document(OTHER, lens + "</lens>\n", MOUNT)
    pieces = read.Pieces()
    assert read.read_pieces(first, pieces) is None
    assert read.read_pieces(second, pieces) is not None
    fresh = read.Pieces()
    assert read.read_pieces(second, fresh) is not None
    alone, with_memo = read_both([first, second, first, second, OTHER.encode()])
    assert with_memo == alone


def test_what_liblensfun_refuses_is_judged_only_when_asked_for(tmp_path):
    data = (
        b'<lensdatabase version="2"><lens><maker>A</maker><model>B</model>'
        b"<mount>M</mount><bogus/></lens></lensdatabase>"
    )
    assert read.read_bytes(data, "a.xml", refusals=True).refusal is not None
    plain = read.read_bytes(data, "a.xml")
    assert (plain.refusal, plain.refusal_judged) == (None, False)
    # Tables kept without the judgement are read again where it is asked for.
    cache = read.Cache(tmp_path / "cache")
    read.read_bytes(data, "a.xml", cache=cache)
    again = read.read_bytes(data, "a.xml", cache=cache, refusals=True)
    assert again.refusal_judged and again.refusal is not None


LENS = """    <lens>
        <maker>Tokina</maker>
        <model>Tokina 11-16mm</model>
        <mount>Nikon F AF</mount>
        <cropfactor>1.5</cropfactor>
        <calibration>
            <distortion model="ptlens" focal="11" a="0.01" b="-0.05" c="0.02"/>
            <distortion model="poly3" focal="16" k1="-0.01"/>
            <tca model="poly3" focal="11" vr="1.0002" vb="0.9998"/>
            <vignetting model="pa" focal="11" aperture="2.8" distance="10" k1="-0.3"/>
        </calibration>
    </lens>
"""
UNICODE = LENS.replace("Tokina 11-16mm", "Tok\xefna 11-16mm")
OTHER = LENS.replace("11-16mm", "12-24mm").replace('a="0.01"', 'a="0.02"')
REAL_FOCAL = OTHER.replace(
    "<calibration>", '<calibration>\n            <real-focal-length focal="11" real-focal="x"/>'
)


CAMERA = """    <camera>
        <maker>Nikon Corporation</maker>
        <model>Nikon D90</model>
        <mount>Nikon F AF</mount>
        <cropfactor>1.523</cropfactor>
    </camera>
"""
MOUNT = """    <mount>
        <name>Nikon F AF</name>
        <name lang="de">Nikon F AF (de)</name>
        <compat>Nikon F</compat>
    </mount>
"""


def document(*parts: str, head: str = "") -> bytes:
    return (head + '<lensdatabase version="2">\n' + "".join(parts) + "</lensdatabase>\n").encode()


#: Documents read after one that teaches the memo LENS and OTHER: each puts
#: the same bytes where they must not be taken for a lens, or in a context
#: that changes what they mean.
MISLEADING = {
    "moved down": document("\n\n\n", OTHER, "<camera><maker>X</maker></camera>\n", LENS),
    "in a comment": document("<!--\n", LENS, "-->\n", OTHER),
    "comment ends inside": document("<!-- ", LENS.replace("</maker>", "</maker> -->", 1), OTHER),
    "in CDATA": document("<camera><![CDATA[\n", LENS, "]]></camera>\n", OTHER),
    "nested": document("<lens>\n", LENS, "</lens>\n"),
    "after the root": document(OTHER) + LENS.encode(),
    "our instruction": document(LENS, "<?lensaudit-piece 0?>\n", OTHER),
    "our instruction first": document("<?lensaudit-piece 0?>\n<!--\n", LENS, "-->\n"),
    "self-closed then a lens": document('<lens a="1"/>', LENS.lstrip()),
    "self-closed, a space, a lens": document('<lens a="1"/>', LENS),
    "instruction text": document(LENS.replace("<maker>", "<maker><?lensaudit-piece 1?>", 1)),
    "latin-1": document(LENS, OTHER.replace("Tokina", "Tok\xefna")).replace(
        "\xef".encode(), b"\xef"
    ),
    "latin-1 declared": b'<?xml version="1.0" encoding="ISO-8859-1"?>\n' + document(UNICODE, OTHER),
    "utf-8 declared": b"<?xml version='1.0' encoding='UTF-8'?>\n" + document(OTHER, UNICODE),
    "namespace": document(LENS.replace("<lens>", '<lens xmlns="urn:x">'), OTHER),
    "entity": document(
        LENS.replace("Tokina</maker>", "&maker;</maker>"),
        head='<!DOCTYPE lensdatabase [<!ENTITY maker "Sigma">]>\n',
    ),
    "attribute default": document(
        LENS, head="<!DOCTYPE lensdatabase [<!ATTLIST distortion a CDATA '0.5'>]>\n"
    ),
    "CRLF": document(LENS, OTHER).replace(b"\n", b"\r\n"),
    "two on a line": document(LENS.rstrip() + OTHER.lstrip()),
    "a line in a message": document(REAL_FOCAL, "\n\n", REAL_FOCAL),
    "broken after": document(LENS, OTHER, "<lens><maker>a</lens>\n"),
    "broken before": document("<camera>\n", LENS, OTHER),
    "truncated": document(LENS, OTHER)[: len(LENS) + 60],
    "root is a lens": LENS.encode(),
    "not a database": b"<lenses>\n" + (LENS + OTHER).encode() + b"</lenses>\n",
    "end tag with space": document(LENS.replace("</lens>", "</lens  >"), OTHER),
    "empty lens": document("<lens/>\n<lens >\n</lens>\n", LENS),
    "tab in start tag": document(LENS.replace("<lens>", "<lens\t>"), OTHER),
    "refused lens": document(OTHER, LENS.replace("<maker>", "<foo/><maker>", 1)),
    "lens refused after": document(LENS, OTHER.replace("<mount>", "<mount lang='x'>", 1)),
    "refused version": document(LENS, OTHER).replace(b'version="2"', b'version="3"'),
    "refused root": b"<maker>\n" + (LENS + OTHER).encode() + b"</maker>\n",
    "byte-order mark": b"\xef\xbb\xbf" + document(LENS, OTHER),
    "comments between": document(MOUNT, "<!-- a -->\n", CAMERA, "  <!--b-->  <!---->", LENS),
    "comment with --": document(LENS, "<!-- a -- b -->\n", OTHER),
    "comment ends --->": document(LENS, "<!-- a --->\n", OTHER),
    "comment not UTF-8": document(LENS, "<!-- \xef -->\n", OTHER).replace("\xef".encode(), b"\xef"),
    "comment with a control character": document(LENS, "<!-- \x01 -->\n", OTHER),
    "text between": document(LENS, "text\n", CAMERA, OTHER),
    "entity between": document(LENS, "&amp;\n", OTHER),
    "unknown entity between": document(LENS, "&bogus;\n", OTHER),
    "instruction between": document(LENS, "<?pi x?>\n", OTHER),
    "element between": document(LENS, "<bogus/>\n", OTHER),
    "element before": document("<bogus/>\n", LENS, OTHER),
    "comment before, text after": document("<!-- a -->", MOUNT, LENS, "text"),
    "all in one comment": document("<!--\n", LENS, OTHER, "-->\n"),
    "pieces in a camera": document("<camera>\n", LENS, MOUNT, "</camera>\n"),
    "a mount in a broken lens": document("<lens>\n<mount>Nikon F AF</mount>\n", MOUNT, LENS),
    "our instruction after": document(LENS, OTHER) + b"<?lensaudit-piece?>\n",
    "our instruction in the root": document(LENS, OTHER, "<?lensaudit-piece?>"),
    "camera refused": document(CAMERA.replace("<maker>", "<bogus/><maker>", 1), LENS),
    "mount end tag with space": document(MOUNT.replace("</mount>", "</mount >"), CAMERA),
    "namespace in a piece known": document(LENS, OTHER.replace("<maker>", '<maker xmlns="u">')),
    "namespace on the root": document(LENS, OTHER).replace(
        b"<lensdatabase ", b'<lensdatabase xmlns="urn:x" '
    ),
    "namespace prefix on the root": document(LENS, OTHER).replace(
        b"<lensdatabase ", b'<lensdatabase xmlns:x="urn:x" '
    ),
    "our instruction in a lens": document(LENS.replace("<mount>", "<?lensaudit-piece?><mount>")),
    "our instruction before the root": b"<?lensaudit-piece?>\n" + document(LENS, OTHER),
    "an end tag first": b"</lens>" + document(LENS, OTHER),
    "many lines": document(LENS, "\n" * 70_000, OTHER),
    "many lines in a comment": document(LENS, "<!--" + "\n" * 70_000 + "-->", OTHER),
}


@pytest.mark.parametrize("name", sorted(MISLEADING))
def test_misleading_documents_read_with_the_memo_as_alone(name):
    teacher = document(MOUNT, CAMERA, LENS, OTHER, REAL_FOCAL, UNICODE)
    contents = [teacher, MISLEADING[name], teacher, MISLEADING[name]]
    for calibrations in (False, True):
        alone, with_memo = read_both(contents, calibrations)
        assert with_memo == alone
    assert pieces_as_whole(contents)[1] == []


SNIPPETS = [
    "<!--",
    "-->",
    "<![CDATA[",
    "]]>",
    "<lens>",
    "</lens>",
    "<?lensaudit-piece 0?>",
    "<?pi x?>",
    "&amp;",
    "&bogus;",
    '"',
    "\n",
    "\r",
    "<camera>",
    "</camera>",
    "<mount>",
    "</mount>",
    "<!-- x -->",
    "\xef",
    CAMERA,
    MOUNT,
    LENS,
]


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    st.lists(st.tuples(st.integers(0, 10_000), st.sampled_from(SNIPPETS)), min_size=1, max_size=4)
)
def test_documents_spliced_anywhere_read_with_the_memo_as_alone(splices):
    teacher = document(MOUNT, LENS, CAMERA, OTHER, REAL_FOCAL)
    text = teacher.decode()
    for position, snippet in splices:
        position %= len(text) + 1
        text = text[:position] + snippet + text[position:]
    contents = [teacher, text.encode(), text.encode("latin-1", "replace")]
    alone, with_memo = read_both(contents)
    assert with_memo == alone
    assert pieces_as_whole(contents)[1] == []


def test_the_memo_is_used_where_it_can_be(monkeypatch):
    pieces = read.Pieces()
    read.read_bytes(document(LENS, OTHER), "a.xml", pieces=pieces)
    learned: list[bytes] = []
    real = read.Pieces._learn
    monkeypatch.setattr(
        read.Pieces,
        "_learn",
        lambda self, kind, piece, v: learned.append(piece) or real(self, kind, piece, v),
    )
    moved = read.read_bytes(document("\n" * 7, OTHER, LENS), "a.xml", pieces=pieces)
    assert learned == []  # both lenses known, on other lines
    assert [row[0] for row in moved.distortion] == [
        row[0] for row in read.read_bytes(document("\n" * 7, OTHER, LENS), "a.xml").distortion
    ]


def test_pieces_with_comments_between_are_read_without_the_document(monkeypatch):
    pieces = read.Pieces()
    teacher = document(MOUNT, CAMERA, LENS, OTHER)
    read.read_bytes(teacher, "a.xml", pieces=pieces)
    from lensaudit.read import xml

    streamed: list[bytes] = []
    real = xml._stream
    monkeypatch.setattr(xml, "_stream", lambda data, *a: streamed.append(data) or real(data, *a))
    learned: list[bytes] = []
    monkeypatch.setattr(read.Pieces, "_learn", lambda self, kind, piece, v: learned.append(piece))
    moved = document("\n<!-- moved -->\n", OTHER, "<!--\n-->", CAMERA, LENS, "\n", MOUNT)
    tables = read.read_bytes(moved, "a.xml", pieces=pieces)
    assert (learned, streamed) == ([], [])  # every piece known, the rest checked alone
    monkeypatch.undo()
    alone = read.read_bytes(moved, "a.xml")
    assert tables_text(tables) == tables_text(alone)
    camera_line = moved[: moved.index(b"<camera>")].count(b"\n") + 1
    assert [row[0] for row in tables.cameras] == [camera_line]


# ---------------------------------------------------------------------------
# The solver's memo
# ---------------------------------------------------------------------------

floats = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 5e-324, -5e-324, 1e308, math.nan, 1.0, 0.5]),
)


def metric_text(columns: dict) -> str:
    return repr(sorted(columns.items()))


@settings(max_examples=200, deadline=None)
@given(
    st.lists(
        st.tuples(st.sampled_from(["ptlens", "poly3", "poly5"]), floats, floats, floats),
        min_size=1,
        max_size=6,
    )
)
def test_the_solver_memo_answers_each_entry_as_solving_it_does(entries):
    rows = []
    for model, *coefficients in entries:
        # Each entry again with its zeros of the other sign.
        for a, b, c in (coefficients, [-v if v == 0 else v for v in coefficients]):
            rows.append((1, "M", "L", (), "rectilinear", 1.5, 1.5, model, 10.0, 10.0,
                         a, b, c, b, c, "ok", ""))  # fmt: skip
    columns = row_columns(rows)
    memo: dict = {}
    first = metric_text(metric_columns(columns, memo))
    again = metric_text(metric_columns(columns, memo))  # every entry from the memo now
    assert first == again == metric_text(metric_columns(columns))


def test_the_solver_memo_tells_zeros_apart():
    pack = struct.Struct("<8d").pack
    assert pack(0.0, *[1.0] * 7) != pack(-0.0, *[1.0] * 7)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=3000), st.binary(max_size=3000), st.binary(max_size=3000))
def test_the_common_start_and_end_of_two_documents_are_found(head, a, b):
    from lensaudit.read import xml

    def naive_prefix(x: bytes, y: bytes) -> int:
        n = 0
        while n < min(len(x), len(y)) and x[n] == y[n]:
            n += 1
        return n

    first, second = head + a, head + b + head
    assert xml._common_prefix(first, second) == naive_prefix(first, second)
    limit = min(len(first), len(second))
    assert xml._common_suffix(first, second, limit) == naive_prefix(first[::-1], second[::-1])
    short = min(7, limit)
    assert xml._common_suffix(first, second, short) == min(
        short, naive_prefix(first[::-1], second[::-1])
    )
