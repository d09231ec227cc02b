"""The reader (lensaudit.read): one record per <distortion>, with its lens context and a status."""

from __future__ import annotations

import math
import xml.etree.ElementTree as StdlibET
from pathlib import Path

import pytest

from conftest import lens_xml
from lensaudit.read import LoadError, read, read_bytes
from lensaudit.read.records import MODEL_COEFFICIENTS, parse_number
from lensaudit.read.tables import SPECS


def load_bytes(data: bytes, name: str) -> list:
    """The distortion entries of one file's content."""
    return read_bytes(data, name).entries()


def only(entries):
    assert len(entries) == 1, entries
    return entries[0]


def test_ptlens_entry_has_lens_context_and_coefficients():
    entry = only(
        load_bytes(
            lens_xml(
                '<distortion model="ptlens" focal="11" a="-0.024" b="-0.002" c="0.005"/>'
            ).encode(),
            "db.xml",
        )
    )
    assert (entry.maker, entry.lens, entry.mounts) == ("Test", "Test 10mm", ("Test Mount",))
    assert (entry.model, entry.focal, entry.a, entry.b, entry.c) == (
        "ptlens",
        11.0,
        -0.024,
        -0.002,
        0.005,
    )
    assert math.isnan(entry.k1) and math.isnan(entry.real_focal)
    assert entry.status == "ok" and entry.message == ""


def test_defaults_type_rectilinear_crop_one_aspect_three_to_two():
    entry = only(
        load_bytes(
            lens_xml('<distortion model="poly3" focal="50" k1="-0.01"/>', cropfactor=None).encode(),
            "db.xml",
        )
    )
    assert (entry.type, entry.crop_factor, entry.aspect_ratio) == ("rectilinear", 1.0, 1.5)


def test_missing_coefficient_is_zero_as_in_liblensfun():
    entry = only(
        load_bytes(lens_xml('<distortion model="ptlens" focal="20" b="0.01"/>').encode(), "db.xml")
    )
    assert (entry.a, entry.b, entry.c) == (0.0, 0.01, 0.0)
    assert entry.status == "ok"


@pytest.mark.parametrize(
    ("text", "ratio"), [("4:3", 4 / 3), ("16:9", 16 / 9), ("1.333", 1.333), ("3:2", 1.5)]
)
def test_aspect_ratio_accepts_ratio_and_decimal_forms(text, ratio):
    entry = only(
        load_bytes(
            lens_xml(
                '<distortion model="poly3" focal="5" k1="0.01"/>',
                extra=f"<aspect-ratio>{text}</aspect-ratio>",
            ).encode(),
            "db.xml",
        )
    )
    assert entry.aspect_ratio == pytest.approx(ratio, rel=1e-15)


def test_calibration_attributes_override_the_lens_crop_and_aspect():
    entry = only(
        load_bytes(
            lens_xml(
                '<distortion model="poly3" focal="5" k1="0.01"/>',
                cropfactor="1.5",
                extra="<aspect-ratio>3:2</aspect-ratio>",
                calibration=' cropfactor="2" aspect-ratio="4:3"',
            ).encode(),
            "db.xml",
        )
    )
    assert (entry.crop_factor, entry.aspect_ratio) == (2.0, pytest.approx(4 / 3))


def test_type_and_real_focal_are_read():
    entry = only(
        load_bytes(
            lens_xml(
                '<distortion model="poly5" focal="8" k1="0.1" k2="-0.01" real-focal="7.9"/>',
                extra="<type>fisheye</type>",
            ).encode(),
            "db.xml",
        )
    )
    assert (entry.type, entry.real_focal, entry.k1, entry.k2) == ("fisheye", 7.9, 0.1, -0.01)


def test_unknown_model_is_kept_with_a_status():
    entry = only(
        load_bytes(lens_xml('<distortion model="acm" focal="8" k1="0.1"/>').encode(), "db.xml")
    )
    assert entry.status == "unknown_model"
    assert "'acm'" in entry.message


def test_missing_focal_is_kept_with_a_status():
    entry = only(load_bytes(lens_xml('<distortion model="poly3" k1="0.1"/>').encode(), "db.xml"))
    assert entry.status == "missing_attribute" and "focal=" in entry.message


def test_missing_model_is_kept_with_a_status():
    entry = only(load_bytes(lens_xml('<distortion focal="8" k1="0.1"/>').encode(), "db.xml"))
    assert entry.status == "missing_attribute" and "model=" in entry.message


@pytest.mark.parametrize("value", ["abc", "0.1.2", "1_0", "", "0x10"])
def test_non_numeric_coefficient_is_a_bad_value(value):
    entry = only(
        load_bytes(
            lens_xml(f'<distortion model="ptlens" focal="8" a="{value}"/>').encode(), "db.xml"
        )
    )
    assert entry.status == "bad_value"
    assert entry.message.startswith("a=")


@pytest.mark.parametrize("value", ["nan", "NaN", "inf", "-Infinity", "1e999"])
def test_non_finite_coefficient_is_a_bad_value(value):
    entry = only(
        load_bytes(
            lens_xml(f'<distortion model="poly3" focal="8" k1="{value}"/>').encode(), "db.xml"
        )
    )
    assert entry.status == "bad_value"
    assert "finite" in entry.message or "overflows" in entry.message


@pytest.mark.parametrize(("attribute", "value"), [("focal", "0"), ("focal", "-5")])
def test_non_positive_focal_is_a_bad_value(attribute, value):
    entry = only(
        load_bytes(
            lens_xml(f'<distortion model="poly3" {attribute}="{value}" k1="0.1"/>').encode(),
            "db.xml",
        )
    )
    assert entry.status == "bad_value" and "not positive" in entry.message


def test_non_positive_crop_factor_makes_its_entries_bad_values():
    entry = only(
        load_bytes(
            lens_xml('<distortion model="poly3" focal="8" k1="0.1"/>', cropfactor="0").encode(),
            "db.xml",
        )
    )
    assert entry.status == "bad_value" and "crop factor" in entry.message


def test_distortion_outside_a_lens_is_reported_not_dropped():
    xml = '<lensdatabase><distortion model="poly3" focal="8" k1="0.1"/></lensdatabase>'
    entry = only(load_bytes(xml.encode(), "db.xml"))
    assert entry.status == "no_lens"


def test_line_numbers_are_source_lines_even_past_removed_calibrations():
    lines = ["<lensdatabase>", "<lens><maker>M</maker><model>L</model><calibration>"]
    lines += [
        '<vignetting model="pa" focal="1" aperture="2" distance="3" k1="0" k2="0" k3="0"/>',
        '<tca model="linear" focal="1" kr="1" kb="1"/>',
        '<vignetting model="pa"\n  focal="1" aperture="2" distance="3" k1="0"/>',
    ]
    lines += [
        '<distortion model="poly3" focal="8" k1="0.1"/>',
        "</calibration></lens>",
        "</lensdatabase>",
    ]
    entry = only(load_bytes("\n".join(lines).encode(), "db.xml"))
    assert entry.line == 7


def test_commented_out_distortion_is_not_an_entry():
    xml = lens_xml(
        '<!-- <distortion model="poly3" focal="8" k1="0.1"/> -->',
        '<distortion model="poly3" focal="9" k1="0.1"/>',
    )
    assert only(load_bytes(xml.encode(), "db.xml")).focal == 9.0


def test_broken_xml_reports_line_and_column_and_salvages_entries():
    xml = lens_xml(
        '<distortion model="poly3" focal="8" k1="0.1"/>',
        '<distortion model="poly3" focal="9" k1="0.2">',
    )  # never closed
    entries = load_bytes(xml.encode(), "db.xml")
    head, *salvaged = entries
    assert head.status == "xml_error"
    assert head.line > 0 and "column" in head.message
    assert [e.focal for e in salvaged] == [8.0, 9.0]
    assert all(e.status == "xml_error" for e in salvaged)


def test_malformed_vignetting_is_still_a_parse_error():
    xml = lens_xml(
        '<vignetting model="pa" focal=1/>', '<distortion model="poly3" focal="8" k1="0.1"/>'
    )
    head = load_bytes(xml.encode(), "db.xml")[0]
    assert head.status == "xml_error" and head.line == 10  # the first calibration line


@pytest.mark.parametrize(
    ("content", "fragment"),
    [
        (b"", "line 1"),
        (
            "<lensdatabase><lens><maker>Caf\u00e9</maker></lens></lensdatabase>".encode("latin-1"),
            "encoding",
        ),
    ],
)
def test_empty_and_non_utf8_files_are_xml_errors(content, fragment):
    head = only(load_bytes(content, "db.xml"))
    assert head.status == "xml_error" and fragment in head.message


def test_external_entity_is_not_fetched(tmp_path):
    secret = tmp_path / "secret.txt"
    secret.write_text("TOPSECRET")
    xml = (
        f'<?xml version="1.0"?>\n<!DOCTYPE d [<!ENTITY x SYSTEM "file://{secret}">]>\n'
        + lens_xml('<distortion model="poly3" focal="8" k1="0.1"/>').replace(
            "<maker>Test</maker>", "<maker>&x;</maker>"
        )
    )
    entries = load_bytes(xml.encode(), "db.xml")
    assert "TOPSECRET" not in repr(entries)
    # liblensfun refuses a file that refers to an entity: so does the reader, naming it.
    assert entries[0].status == "xml_error" and "&x;" in entries[0].message


def test_entity_expansion_bomb_is_not_expanded():
    entities = '<!ENTITY a0 "lol">' + "".join(
        f'<!ENTITY a{i} "{"&a" + str(i - 1) + ";" * 1}{"&a" + str(i - 1) + ";"}">'
        for i in range(1, 40)
    )
    xml = f"<!DOCTYPE d [{entities}]>\n" + lens_xml(
        '<distortion model="poly3" focal="8" k1="0.1"/>'
    ).replace("<maker>Test</maker>", "<maker>&a39;</maker>")
    entries = load_bytes(xml.encode(), "db.xml")
    assert len(repr(entries)) < 10_000
    assert entries[0].status == "xml_error" and "&a39;" in entries[0].message


def test_directory_names_are_relative_to_the_path_given(write_xml):
    path = write_xml(lens_xml('<distortion model="poly3" focal="8" k1="0.1"/>'), "a.xml")
    result = read(path.parent)
    assert [e.file for e in result.entries()] == ["a.xml"]
    assert [f.name for f in result.files] == ["a.xml"]


def test_missing_path_and_empty_directory_are_load_errors(tmp_path):
    with pytest.raises(LoadError, match="no such file"):
        read(tmp_path / "nope")
    with pytest.raises(LoadError) as empty:
        read(tmp_path)
    assert str(empty.value) == (
        f"{tmp_path}: directory holds no *.xml files (give a Lensfun database directory, "
        "a Lensfun checkout, or XML files)"
    )


def test_every_distortion_element_of_the_bundled_database_is_loaded(bundled_db: Path):
    # Counted independently with the standard library's parser.
    expected = []
    for file in sorted(bundled_db.glob("*.xml")):
        for element in StdlibET.parse(file).getroot().iter("distortion"):
            expected.append((file.name, element.get("model"), float(element.get("focal"))))
    entries = read(bundled_db).entries()
    assert [(e.file, e.model, e.focal) for e in entries] == expected
    assert all(e.status == "ok" for e in entries)


def test_bundled_database_matches_liblensfun(bundled_db: Path):
    """Every calibration liblensfun reads, lensaudit reads with the same values.

    liblensfun keeps single-precision floats, so values are compared at that
    precision. It also drops what the database defines twice (a second entry
    for a focal length already calibrated, a second lens of the same maker
    and model), which lensaudit keeps and reports.
    """
    lensfunpy = pytest.importorskip("lensfunpy")
    import numpy as np

    def single(*values):
        return tuple(np.float32(values).tolist())

    ours: dict = {}
    for e in read(bundled_db).entries():
        coefficients = {"ptlens": (e.a, e.b, e.c), "poly3": (e.k1,), "poly5": (e.k1, e.k2)}
        ours.setdefault((e.maker, e.lens, single(e.crop_factor)), {}).setdefault(
            single(e.focal), set()
        ).add((e.model, single(*coefficients[e.model])))
    theirs: dict = {}
    lenses = lensfunpy.Database().lenses
    names = {(lens.maker.strip(), lens.model.strip()) for lens in lenses}
    for lens in lenses:
        key = (lens.maker.strip(), lens.model.strip(), single(lens.crop_factor))
        for calib in lens.calib_distortion:
            model = calib.model.name.lower()
            count = len(MODEL_COEFFICIENTS[model])
            theirs.setdefault(key, {})[single(calib.focal)] = (model, single(*calib.terms[:count]))

    assert theirs.keys() <= ours.keys()
    assert all((maker, model) in names for maker, model, _ in ours.keys() - theirs.keys())
    for key, calibrations in theirs.items():
        assert calibrations.keys() == ours[key].keys(), key
        for focal, calibration in calibrations.items():
            assert calibration in ours[key][focal], (key, focal)


def test_parse_number_rejects_python_only_spellings():
    assert parse_number(" -1.5e-3 ") == -1.5e-3
    for text in ("nan", "inf", "1_000", "\u0661", "1e400"):
        with pytest.raises(ValueError):
            parse_number(text)


@pytest.mark.parametrize(
    "text",
    ["1\u00a0", "\u00a01.5", "\uff11", "1\uff10", "\u0661.5"],
    ids=[
        "trailing no-break space",
        "leading no-break space",
        "full-width 1",
        "full-width 0",
        "arabic-indic digit",
    ],
)
def test_a_no_break_space_or_a_digit_that_is_not_ascii_is_not_a_number(text):
    # Python's float() takes all of these; Lensfun's numbers are plain ASCII decimals.
    assert float(text) == float(text)
    with pytest.raises(ValueError, match="is not a number"):
        parse_number(text)
    entry = only(
        load_bytes(lens_xml(f'<distortion model="poly3" focal="8" k1="{text}"/>').encode(), "x")
    )
    assert entry.status == "bad_value" and "is not a number" in entry.message


def test_real_focal_length_element_of_version_1_databases_is_read():
    xml = lens_xml(
        '<distortion model="ptlens" focal="4.9" a="0.0132" b="-0.07765" c="0.14683"/>',
        '<distortion model="ptlens" focal="6" a="0.01" b="-0.07" c="0.1"/>',
        '<real-focal-length focal="4.9" real-focal="3.2"/>',
    )
    first, second = load_bytes(xml.encode(), "db.xml")
    assert first.real_focal == 3.2 and first.status == "ok"
    assert math.isnan(second.real_focal)


def test_real_focal_attribute_wins_over_the_element():
    xml = lens_xml(
        '<distortion model="poly3" focal="5" k1="0.01" real-focal="4.5"/>',
        '<real-focal-length focal="5" real-focal="3.2"/>',
    )
    assert only(load_bytes(xml.encode(), "db.xml")).real_focal == 4.5


def test_long_bad_values_are_cut_short_in_messages():
    entry = only(
        load_bytes(
            lens_xml(f'<distortion model="poly3" focal="8" k1="{"9" * 5000}"/>').encode(), "db.xml"
        )
    )
    assert entry.status == "bad_value" and len(entry.message) < 200


#: <maker> texts split by comments, and what liblensfun makes of them: the last
#: piece of text that is not blank (GMarkup hands each piece over on its own).
SPLIT_TEXTS = [
    ("Tok<!---->ina", "ina"),
    ("Tok<!-- a comment -->ina", "ina"),
    ("Tokina<!---->   ", "Tokina"),
    ("  <!---->Tokina", "Tokina"),
    ("To<!---->ki<!---->na", "na"),
]


@pytest.mark.parametrize(("maker", "expected"), SPLIT_TEXTS)
def test_text_split_by_a_comment_is_its_last_piece(maker, expected):
    xml = lens_xml('<distortion model="poly3" focal="8" k1="0.1"/>').replace(
        "<maker>Test</maker>", f"<maker>{maker}</maker>"
    )
    assert only(load_bytes(xml.encode(), "db.xml")).maker == expected


@pytest.mark.parametrize(("maker", "expected"), SPLIT_TEXTS)
def test_text_split_by_a_comment_is_read_as_liblensfun_master_reads_it(maker, expected):
    from liblensfun_master import lenses

    xml = lens_xml('<distortion model="poly3" focal="8" k1="0.1"/>').replace(
        "<maker>Test</maker>", f"<maker>{maker}</maker>"
    )
    [lens] = lenses(xml.encode())
    assert lens["maker"].strip() == expected


CDATA_JOINED = pytest.mark.xfail(
    strict=True,
    reason="a CDATA section splits text for liblensfun (GMarkup hands each piece over on its "
    "own), but libxml2 joins it to the text around it; no Lensfun file has CDATA",
)


@pytest.mark.parametrize(
    "maker", ["Tok<?pi x?>ina", pytest.param("Tok<![CDATA[in]]>a", marks=CDATA_JOINED)]
)
def test_text_split_by_other_markup_is_read_as_liblensfun_master_reads_it(maker):
    from liblensfun_master import lenses

    xml = lens_xml('<distortion model="poly3" focal="8" k1="0.1"/>').replace(
        "<maker>Test</maker>", f"<maker>{maker}</maker>"
    )
    [lens] = lenses(xml.encode())
    assert only(load_bytes(xml.encode(), "db.xml")).maker == lens["maker"].strip()


def test_calibrations_of_one_point_share_its_numbers_and_keep_their_own():
    # A file's vignetting rows repeat a few focal lengths, apertures and
    # distances: one float each, whatever the rows (memory), with the value
    # and sign of each text.
    xml = lens_xml(
        '<vignetting model="pa" focal="24" aperture="2.8" distance="10" k1="-0.5"/>',
        '<vignetting model="pa" focal="24" aperture="2.8" distance="1e3" k1="-0.25"/>',
        '<vignetting model="pa" focal="24.0" aperture="4" distance="10" k1="-0.5"/>',
        '<vignetting model="pa" focal="-24" aperture="4" distance="10" k1="-0.5"/>',
    )
    rows = read_bytes(xml.encode(), "db.xml", calibrations=True).vignetting
    fields = SPECS["vignetting"].row_fields
    focal, aperture, distance, k1 = map(fields.index, ("focal", "aperture", "distance", "k1"))
    assert [row[focal] for row in rows[:3]] == [24.0, 24.0, 24.0]
    assert rows[0][focal] is rows[1][focal] and rows[0][aperture] is rows[1][aperture]
    assert rows[0][distance] is rows[2][distance] and rows[1][distance] == 1000.0
    assert [row[k1] for row in rows[:3]] == [-0.5, -0.25, -0.5]
    assert rows[3][-2] != "ok" and "focal" in rows[3][-1]  # not positive: examined in full
