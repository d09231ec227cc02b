"""Gyroflow lens profiles: one file into one record, a tree into its files, and
which database a path is.

Small profiles are written here, each broken in one way, and the record of
each must carry the status and the line of the key at fault, found by the
test in the text it wrote. On Gyroflow's own database (the shared tarball,
skipped with a reason where it is absent), the reader's counts of usable and
unusable profiles, by reason, must be those of a plain count with json.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tarfile
from collections import Counter
from pathlib import Path

import pytest

from conftest import lens_xml
from lensaudit.read import (
    GYROFLOW,
    LENSFUN,
    LoadError,
    database_format,
    gyroflow,
    read_gyroflow,
)
from lensaudit.read.gyroflow import Profile, is_profile, read_profile
from lensaudit.read.paths import expand, gyroflow_entries, gyroflow_files

TARBALL = (
    Path(__file__).resolve().parents[2]
    / "shared"
    / "data"
    / "gyroflow-lens-profiles-886fc616.tar.gz"
)
#: Gyroflow's database as of the tarball (its README and docs/gyroflow.md).
REAL_PROFILES = 9810

NAME = "Brand/profile.json"


def profile(**changes: object) -> dict:
    """A profile as Gyroflow writes one; ``changes`` set top-level keys, or keys of
    ``fisheye_params`` and ``calib_dimension`` written ``fisheye_params.KEY``;
    a value of ``...`` removes the key."""
    value: dict = {
        "name": "Brand_Camera_Lens_4k_16by9_3840x2160-25.00fps",
        "note": "",
        "calibrated_by": "Test",
        "camera_brand": "Brand",
        "camera_model": "Camera",
        "lens_model": "Lens 12mm",
        "camera_setting": "4k",
        "calib_dimension": {"w": 3840, "h": 2160},
        "orig_dimension": {"w": 3840, "h": 2160},
        "input_horizontal_stretch": 1.0,
        "input_vertical_stretch": 1.0,
        "num_images": 12,
        "fps": 25.0,
        "official": False,
        "asymmetrical": False,
        "digital_lens": None,
        "fisheye_params": {
            "RMS_error": 0.5,
            "camera_matrix": [[1800.5, 0.0, 1920.25], [0.0, 1801.5, 1080.75], [0.0, 0.0, 1.0]],
            "distortion_coeffs": [0.05, -0.01, 0.002, -0.0004],
            "radial_distortion_limit": None,
        },
        "calib_params": {"RMS_error": 0.0, "camera_matrix": [], "distortion_coeffs": []},
        "distortion_model": None,
    }
    for key, new in changes.items():
        place, _, inner = key.rpartition(".")
        target = value[place] if place else value
        if new is ...:
            target.pop(inner, None)
        else:
            target[inner] = new
    return value


def text_of(value: object) -> str:
    """JSON as Gyroflow writes it: two spaces of indent."""
    return json.dumps(value, indent=2)


def key_line(text: str, key: str, after: str | None = None) -> int:
    """The line of ``"key":`` in ``text`` (after the line of ``"after":``), counted
    by the test alone."""
    lines = text.split("\n")
    start = 0
    if after is not None:
        start = next(i for i, line in enumerate(lines) if f'"{after}":' in line)
    return next(i for i, line in enumerate(lines) if i >= start and f'"{key}":' in line) + 1


def read_text(text: str | bytes) -> Profile:
    data = text.encode() if isinstance(text, str) else text
    return read_profile(data, NAME)


# ---------------------------------------------------------------------------
# Usable profiles
# ---------------------------------------------------------------------------


def test_a_profile_is_read_into_every_field_with_the_line_of_its_coefficients():
    text = text_of(profile())
    found = read_text(text)
    assert found == Profile(
        file=NAME,
        line=key_line(text, "distortion_coeffs", after="fisheye_params"),
        camera_brand="Brand",
        camera_model="Camera",
        lens_model="Lens 12mm",
        camera_setting="4k",
        name="Brand_Camera_Lens_4k_16by9_3840x2160-25.00fps",
        w=3840,
        h=2160,
        fx=1800.5,
        fy=1801.5,
        cx=1920.25,
        cy=1080.75,
        k1=0.05,
        k2=-0.01,
        k3=0.002,
        k4=-0.0004,
        official=False,
        digital_lens="",
        asymmetrical=False,
        horizontal_stretch=1.0,
        vertical_stretch=1.0,
        rms_error=0.5,
        radial_distortion_limit=found.radial_distortion_limit,
        status="ok",
        message="",
    )
    assert math.isnan(found.radial_distortion_limit)


def test_the_line_is_that_of_fisheye_params_coefficients_not_an_earlier_key_of_that_name():
    # calib_params (and a zoom's interpolations) hold distortion_coeffs too.
    value = profile()
    value = {"interpolations": {"24": {"distortion_coeffs": [0, 0, 0, 0]}}, **value}
    text = text_of(value)
    assert read_text(text).line == key_line(text, "distortion_coeffs", after="fisheye_params")
    assert read_text(text).line != key_line(text, "distortion_coeffs")


def test_a_folding_profile_is_read_as_it_is_the_reader_does_not_judge_it():
    # theta_d = theta (1 - 0.5 theta^2) turns back at theta = sqrt(2/3): the audit's to say.
    text = text_of(profile(**{"fisheye_params.distortion_coeffs": [-0.5, 0.0, 0.0, 0.0]}))
    found = read_text(text)
    assert (found.status, found.k1, found.k2, found.k3, found.k4) == ("ok", -0.5, 0.0, 0.0, 0.0)


def test_a_stretched_profile_keeps_its_stretch_and_an_absent_one_is_1():
    found = read_text(text_of(profile(input_horizontal_stretch=1.33, input_vertical_stretch=...)))
    assert (found.status, found.horizontal_stretch, found.vertical_stretch) == ("ok", 1.33, 1.0)
    found = read_text(text_of(profile(input_horizontal_stretch=2, input_vertical_stretch=None)))
    assert (found.status, found.horizontal_stretch, found.vertical_stretch) == ("ok", 2.0, 1.0)


def test_all_zero_coefficients_are_usable():
    found = read_text(text_of(profile(**{"fisheye_params.distortion_coeffs": [0.0] * 4})))
    assert found.status == "ok" and (found.k1, found.k2, found.k3, found.k4) == (0, 0, 0, 0)


def test_flags_digital_lens_and_limits_as_written_and_absent_ones_at_their_defaults():
    found = read_text(
        text_of(
            profile(
                official=True,
                asymmetrical=True,
                digital_lens="gopro_superview",
                **{"fisheye_params.radial_distortion_limit": 3.7},
            )
        )
    )
    assert (found.official, found.asymmetrical, found.digital_lens) == (
        True,
        True,
        "gopro_superview",
    )
    assert found.radial_distortion_limit == 3.7 and found.status == "ok"
    bare = {
        "calib_dimension": {"w": 1920, "h": 1080},
        "fisheye_params": {
            "camera_matrix": [[1000, 0, 960], [0, 1000, 540], [0, 0, 1]],
            "distortion_coeffs": [0, 0, 0, 0],
        },
    }
    found = read_text(text_of(bare))
    assert found.status == "ok", found.message
    assert (found.official, found.asymmetrical, found.digital_lens, found.camera_brand) == (
        False,
        False,
        "",
        "",
    )
    assert (found.fx, found.cx, found.horizontal_stretch) == (1000.0, 960.0, 1.0)
    assert math.isnan(found.rms_error) and math.isnan(found.radial_distortion_limit)


def test_a_principal_point_outside_the_frame_is_kept():
    # 82 of Gyroflow's profiles have one; where the image is, is the audit's to say.
    matrix = [[1800.0, 0.0, -748.0], [0.0, 1800.0, 3000.0], [0.0, 0.0, 1.0]]
    found = read_text(text_of(profile(**{"fisheye_params.camera_matrix": matrix})))
    assert (found.status, found.cx, found.cy) == ("ok", -748.0, 3000.0)


# ---------------------------------------------------------------------------
# Broken profiles: each a status, and the line of the key at fault
# ---------------------------------------------------------------------------

FIELD_CASES = {
    # name: (changes, status, key at fault, whether under fisheye_params, words of the message)
    "no camera matrix": (
        {"fisheye_params.camera_matrix": ...},
        "missing_attribute",
        "fisheye_params",
        False,
        "fisheye_params has no camera_matrix",
    ),
    "no coefficients": (
        {"fisheye_params.distortion_coeffs": ...},
        "missing_attribute",
        "fisheye_params",
        False,
        "fisheye_params has no distortion_coeffs",
    ),
    "no calib_dimension": (
        {"calib_dimension": ...},
        "missing_attribute",
        "fisheye_params",
        False,
        "no calib_dimension",
    ),
    "no fisheye_params": (
        {"fisheye_params": ...},
        "missing_attribute",
        "calib_dimension",
        False,
        "no fisheye_params",
    ),
    "no h": ({"calib_dimension.h": ...}, "missing_attribute", "calib_dimension", False, "no h"),
    "zero width": (
        {"calib_dimension.w": 0},
        "bad_value",
        "calib_dimension",
        False,
        "w 0 is not a positive whole number",
    ),
    "negative height": (
        {"calib_dimension.h": -5},
        "bad_value",
        "calib_dimension",
        False,
        "h -5 is not",
    ),
    "fractional width": (
        {"calib_dimension.w": 1920.5},
        "bad_value",
        "calib_dimension",
        False,
        "w 1920.5 is not",
    ),
    "width as text": (
        {"calib_dimension.w": "1920"},
        "bad_value",
        "calib_dimension",
        False,
        "w the string '1920'",
    ),
    "width true": ({"calib_dimension.w": True}, "bad_value", "calib_dimension", False, "w true"),
    "width of 400 digits": (
        {"calib_dimension.w": 10**400},
        "bad_value",
        "calib_dimension",
        False,
        "is not a positive whole number",
    ),
    "calib_dimension a list": (
        {"calib_dimension": [1920, 1080]},
        "bad_value",
        "calib_dimension",
        False,
        "not an object",
    ),
    "negative focal lengths": (
        {"fisheye_params.camera_matrix": [[-506.4, 0.0, 960.0], [0.0, -505.9, 540.0], [0, 0, 1]]},
        "bad_value",
        "camera_matrix",
        True,
        "fx -506.4 is not positive",
    ),
    "singular matrix": (
        {"fisheye_params.camera_matrix": [[1000.0, 0.0, 960.0], [0.0, 0.0, 540.0], [0, 0, 1]]},
        "bad_value",
        "camera_matrix",
        True,
        "fy 0.0 is not positive",
    ),
    "all-zero matrix": (
        {"fisheye_params.camera_matrix": [[0, 0, 0], [0, 0, 0], [0, 0, 0]]},
        "bad_value",
        "camera_matrix",
        True,
        "not of the form",
    ),
    "2x2 matrix": (
        {"fisheye_params.camera_matrix": [[1000.0, 0.0], [0.0, 1000.0]]},
        "bad_value",
        "camera_matrix",
        True,
        "not 3 rows of 3 numbers",
    ),
    "empty matrix": (
        {"fisheye_params.camera_matrix": []},
        "bad_value",
        "camera_matrix",
        True,
        "not 3 rows of 3 numbers",
    ),
    "skewed matrix": (
        {"fisheye_params.camera_matrix": [[1000.0, 2.0, 960.0], [0.0, 1000.0, 540.0], [0, 0, 1]]},
        "bad_value",
        "camera_matrix",
        True,
        "[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]",
    ),
    "matrix entry null": (
        {"fisheye_params.camera_matrix": [[1000.0, 0.0, None], [0.0, 1000.0, 540.0], [0, 0, 1]]},
        "bad_value",
        "camera_matrix",
        True,
        "camera_matrix[0][2] is null, not a number",
    ),
    "three coefficients": (
        {"fisheye_params.distortion_coeffs": [0.1, 0.01, 0.001]},
        "bad_value",
        "distortion_coeffs",
        True,
        "holds 3 numbers, not 4",
    ),
    "five coefficients": (
        {"fisheye_params.distortion_coeffs": [0.1, 0.01, 0.001, 0.0, 0.0]},
        "bad_value",
        "distortion_coeffs",
        True,
        "holds 5 numbers, not 4",
    ),
    "no coefficient": (
        {"fisheye_params.distortion_coeffs": []},
        "bad_value",
        "distortion_coeffs",
        True,
        "holds 0 numbers",
    ),
    "coefficients null": (
        {"fisheye_params.distortion_coeffs": None},
        "bad_value",
        "distortion_coeffs",
        True,
        "is null, not 4 numbers",
    ),
    "coefficient null": (
        {"fisheye_params.distortion_coeffs": [0.1, None, 0.0, 0.0]},
        "bad_value",
        "distortion_coeffs",
        True,
        "k2 is null",
    ),
    "coefficient as text": (
        {"fisheye_params.distortion_coeffs": [0.1, 0.0, "0.5", 0.0]},
        "bad_value",
        "distortion_coeffs",
        True,
        "k3 is the string '0.5'",
    ),
    "coefficient false": (
        {"fisheye_params.distortion_coeffs": [0.1, 0.0, 0.0, False]},
        "bad_value",
        "distortion_coeffs",
        True,
        "k4 is false",
    ),
    "fisheye_params a list": (
        {"fisheye_params": [1, 2]},
        "bad_value",
        "fisheye_params",
        False,
        "fisheye_params is an array",
    ),
    "zero stretch": (
        {"input_horizontal_stretch": 0},
        "bad_value",
        "input_horizontal_stretch",
        False,
        "is not a positive number",
    ),
    "negative stretch": (
        {"input_vertical_stretch": -1.5},
        "bad_value",
        "input_vertical_stretch",
        False,
        "is not a positive number",
    ),
    "stretch as text": (
        {"input_vertical_stretch": "1.33"},
        "bad_value",
        "input_vertical_stretch",
        False,
        "the string",
    ),
    "negative RMS error": (
        {"fisheye_params.RMS_error": -1.0},
        "bad_value",
        "RMS_error",
        True,
        "RMS_error -1.0 is not a number >= 0",
    ),
    "negative radial limit": (
        {"fisheye_params.radial_distortion_limit": -0.5},
        "bad_value",
        "radial_distortion_limit",
        True,
        "radial_distortion_limit -0.5",
    ),
    "official as text": ({"official": "yes"}, "bad_value", "official", False, "not true or false"),
    "digital lens true": (
        {"digital_lens": True},
        "bad_value",
        "digital_lens",
        False,
        "not a string",
    ),
    "brand a number": ({"camera_brand": 5}, "bad_value", "camera_brand", False, "not a string"),
    "another model": (
        {"distortion_model": "poly3"},
        "unknown_model",
        "distortion_model",
        False,
        "not OpenCV's fisheye model",
    ),
    "another model id": (
        {"distortion_model_id": 2},
        "unknown_model",
        "distortion_model_id",
        False,
        "not OpenCV's fisheye model",
    ),
    "OpenCV's standard model": (
        {"use_opencv_standard": True, "use_opencv_fisheye": False},
        "unknown_model",
        "use_opencv_standard",
        False,
        "not OpenCV's fisheye model",
    ),
}


@pytest.mark.parametrize("case", FIELD_CASES)
def test_a_field_the_audit_cannot_use_is_a_status_on_the_line_of_its_key(case):
    changes, status, key, nested, words = FIELD_CASES[case]
    text = text_of(profile(**changes))
    found = read_text(text)
    line = key_line(text, key, after="fisheye_params" if nested else None)
    assert found.status == status, found.message
    assert found.message.startswith(f"{NAME}:{line}: "), found.message
    assert words in found.message
    assert "\n" not in found.message


def test_a_field_at_fault_leaves_nan_or_zero_never_a_wrong_number():
    found = read_text(text_of(profile(**{"fisheye_params.distortion_coeffs": [0.1, None, 0, 0]})))
    assert found.k1 == 0.1 and math.isnan(found.k2)
    found = read_text(text_of(profile(**{"calib_dimension.w": -1})))
    assert (found.w, found.h) == (0, 2160)


def test_every_problem_is_said_the_most_basic_status_first():
    changes = {"calib_dimension.w": 0, "fisheye_params.distortion_coeffs": ...}
    text = text_of(profile(**changes))
    found = read_text(text)
    assert found.status == "missing_attribute"
    assert found.message == (
        f"{NAME}:{key_line(text, 'calib_dimension')}: calib_dimension w 0 is not a positive "
        f"whole number of pixels; line {key_line(text, 'fisheye_params')}: "
        "fisheye_params has no distortion_coeffs"
    )


def replace_once(text: str, old: str, new: str) -> str:
    assert text.count(old) == 1, old
    return text.replace(old, new)


def coefficients_text(*written: str) -> str:
    """A profile whose coefficients are written as given (JSON or not)."""
    text = text_of(profile(**{"fisheye_params.distortion_coeffs": [7.5, 8.5, 9.5, 10.5]}))
    for number, new in zip(("7.5", "8.5", "9.5", "10.5"), written, strict=False):
        text = replace_once(text, number, new)
    return text


@pytest.mark.parametrize(
    ("literal", "words"),
    [
        ("NaN", "k1 is NaN, which JSON does not allow"),
        ("-Infinity", "k1 is not finite"),
        ("Infinity", "k1 is not finite"),
        ("1e999", "k1 is not finite"),
        ("-1e400", "k1 is not finite"),
    ],
)
def test_nan_infinity_and_numbers_beyond_a_double_are_bad_values(literal, words):
    text = coefficients_text(literal)
    found = read_text(text)
    line = key_line(text, "distortion_coeffs", after="fisheye_params")
    assert (found.status, found.line) == ("bad_value", line)
    assert found.message == f"{NAME}:{line}: distortion_coeffs {words}"


def test_nan_in_a_field_the_audit_does_not_use_is_still_a_bad_value():
    text = replace_once(text_of(profile()), '"fps": 25.0', '"fps": NaN')
    found = read_text(text)
    assert found.status == "bad_value"
    assert found.message == f"{NAME}:{key_line(text, 'fps')}: NaN or Infinity is not a JSON number"


def test_the_words_nan_and_infinity_in_a_string_are_text():
    found = read_text(text_of(profile(note="NaN Infinity -Infinity")))
    assert found.status == "ok", found.message


def test_an_integer_of_thousands_of_digits_is_a_bad_value_not_a_traceback():
    text = replace_once(text_of(profile()), '"num_images": 12', '"num_images": ' + "9" * 5000)
    found = read_text(text)
    assert found.status == "bad_value"
    assert found.message.startswith(f"{NAME}:{key_line(text, 'num_images')}: an integer of more")


def json_error_line(text: str) -> tuple[int, int]:
    """(line, column) where Python's json stops reading ``text``."""
    with pytest.raises(json.JSONDecodeError) as error:
        json.loads(text)
    return error.value.lineno, error.value.colno


@pytest.mark.parametrize(
    "text",
    [
        text_of(profile())[:-40],  # cut short
        replace_once(text_of(profile()), '"fps": 25.0,', '"fps": 25.0,,'),
        replace_once(text_of(profile()), '"fps": 25.0,', "'fps': 25.0,"),
        text_of(profile()) + "\n}",  # something after the object
        "",
        "   \n",
    ],
    ids=["truncated", "double comma", "single quotes", "trailing brace", "empty", "blank"],
)
def test_text_that_is_not_json_is_a_json_error_where_json_stops(text):
    line, column = json_error_line(text)
    found = read_text(text)
    assert (found.status, found.line) == ("json_error", line)
    assert found.message.startswith(f"{NAME}:{line}: not valid JSON: ")
    assert found.message.endswith(f"(column {column})")


def test_a_byte_that_is_not_utf8_is_a_json_error_on_its_line():
    data = text_of(profile()).encode()
    line = key_line(data.decode(), "lens_model")
    data = data.replace(b"Lens 12mm", b"Lens \xff12mm")
    found = read_text(data)
    assert (found.status, found.line) == ("json_error", line)
    assert found.message == f"{NAME}:{line}: not valid JSON: byte 0xff is not UTF-8"


@pytest.mark.parametrize(
    ("encoded", "words"),
    [
        (b"\xef\xbb\xbf" + text_of(profile()).encode(), "a UTF-8 byte-order mark"),
        (text_of(profile()).encode("utf-16"), "a UTF-16 (or UTF-32) byte-order mark"),
        (text_of(profile()).encode("utf-16-be"), "a NUL byte (UTF-16 or UTF-32?)"),
    ],
    ids=["utf-8 bom", "utf-16", "utf-16 without bom"],
)
def test_a_byte_order_mark_or_another_encoding_is_a_json_error(encoded, words):
    found = read_text(encoded)
    assert found.status == "json_error" and words in found.message


@pytest.mark.parametrize("depth", [1000, 100_000])
def test_deep_nesting_is_a_status_never_a_recursion_error(depth):
    text = '{"fisheye_params": ' + "[" * depth + "]" * depth + "}"
    found = read_text(text)
    assert found.status in ("json_error", "bad_value") and found.message.startswith(NAME)


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("[1, 2]", "the JSON is an array, not an object"),
        ('"profile"', "the JSON is the string 'profile', not an object"),
        ("null", "the JSON is null, not an object"),
        ('{"name": "a preset", "stabilization": {}}', "no calib_dimension or fisheye_params"),
    ],
)
def test_json_that_is_not_a_profile_is_not_a_database(text, words):
    found = read_text(text)
    assert found.status == "not_database"
    assert found.message == f"{NAME}:1: not a Gyroflow lens profile: {words}"
    assert not is_profile(text.encode())


def test_an_enormous_file_is_not_read_as_a_profile():
    data = text_of(profile(note="x" * (gyroflow.MAX_PROFILE_BYTES + 1))).encode()
    found = read_text(data)
    assert (found.status, found.line) == ("not_database", 0)
    assert found.message == f"{NAME}: larger than 1 MiB, not a Gyroflow lens profile"
    assert not is_profile(data)


def hand_cases() -> list[str]:
    """The text of every profile written above that parses."""
    texts = [text_of(profile(**changes)) for changes, *_ in FIELD_CASES.values()]
    texts += [text_of(profile(**{"fisheye_params.distortion_coeffs": [0.0] * 4}))]
    texts += [text_of(profile(input_horizontal_stretch=2, distortion_model="opencv_fisheye"))]
    texts += [coefficients_text(literal) for literal in ("NaN", "Infinity", "1e999")]
    return texts


@pytest.mark.parametrize("text", hand_cases())
def test_the_fast_path_gives_what_the_field_by_field_check_gives(text):
    value = json.loads(text)
    constants = "NaN" in text or "Infinity" in text
    checked = gyroflow._Fields(text, NAME).profile(value, constants)
    assert repr(read_text(text)) == repr(checked)  # repr: NaN equals NaN


# ---------------------------------------------------------------------------
# Directories: which files, which format
# ---------------------------------------------------------------------------


def write(path: Path, content: str | bytes) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(content, str):
        content = content.encode()
    path.write_bytes(content)
    return path


def make_tree(root: Path) -> Path:
    """A lens_profiles checkout in small: brands, phones by maker, the
    repository's own files and a JSON file that is not a profile."""
    good = text_of(profile())
    write(root / "GoPro" / "GoPro_HERO.json", good)
    write(root / "GoPro" / "GoPro_HERO (2).json", text_of(profile(camera_model="HERO (2)")))
    write(root / "Mobile phones" / "Apple" / "Apple_iPhone.json", good)
    write(root / "Sony" / "Sony_a7_UPPER.JSON", good)
    write(root / "Sony" / "broken.json", good[:-30])
    write(root / "Other" / "preset.json", '{"name": "not a profile"}')
    write(root / "LICENSE", "CC0 1.0 Universal")
    write(root / "compress.rs", "fn main() {}")
    write(root / ".github" / "workflows" / "release.yml", "name: Release")
    write(root / ".github" / "hidden.json", good)
    write(root / "Sony" / ".hidden.json", good)
    return root


TREE_FILES = [
    "GoPro/GoPro_HERO (2).json",
    "GoPro/GoPro_HERO.json",
    "Mobile phones/Apple/Apple_iPhone.json",
    "Other/preset.json",
    "Sony/Sony_a7_UPPER.JSON",
    "Sony/broken.json",
]


def test_a_tree_of_profiles_is_every_json_file_at_any_depth_outside_hidden_directories(tmp_path):
    root = make_tree(tmp_path / "lens_profiles")
    assert [name for name, _ in gyroflow_entries(root)] == TREE_FILES
    assert gyroflow_files(root) == [(str(root.resolve() / name), name) for name in TREE_FILES]


def test_each_file_of_a_tree_is_one_record_and_what_is_not_a_profile_says_so(tmp_path):
    root = make_tree(tmp_path / "lens_profiles")
    found = read_gyroflow(root)
    assert [(p.file, p.status) for p in found] == [
        ("GoPro/GoPro_HERO (2).json", "ok"),
        ("GoPro/GoPro_HERO.json", "ok"),
        ("Mobile phones/Apple/Apple_iPhone.json", "ok"),
        ("Other/preset.json", "not_database"),
        ("Sony/Sony_a7_UPPER.JSON", "ok"),
        ("Sony/broken.json", "json_error"),
    ]


def test_links_are_followed_once_and_a_loop_does_not_hang(tmp_path):
    root = make_tree(tmp_path / "lens_profiles")
    outside = write(tmp_path / "elsewhere" / "Linked.json", text_of(profile()))
    (root / "Linked").mkdir()
    os.symlink(outside, root / "Linked" / "Linked.json")
    os.symlink(root, root / "Other" / "loop")
    os.symlink(tmp_path / "nowhere.json", root / "Other" / "dangling.json")
    found = {p.file: p for p in read_gyroflow(root)}
    assert found["Linked/Linked.json"].status == "ok"
    assert found["Other/dangling.json"].status == "unreadable"
    assert found["Other/dangling.json"].message.startswith("Other/dangling.json: cannot read file")
    assert not any(name.startswith("Other/loop") for name in found)


def test_a_fifo_named_as_a_profile_is_unreadable_and_does_not_block(tmp_path):
    root = make_tree(tmp_path / "lens_profiles")
    os.mkfifo(root / "GoPro" / "fifo.json")
    found = {p.file: p for p in read_gyroflow(root)}
    assert found["GoPro/fifo.json"].status == "unreadable"
    assert "not a regular file" in found["GoPro/fifo.json"].message


def test_which_format_a_path_is(tmp_path, write_xml, bundled_db):
    root = make_tree(tmp_path / "lens_profiles")
    assert database_format(root) == GYROFLOW
    assert database_format(root / "GoPro" / "GoPro_HERO.json") == GYROFLOW
    # By content: a profile named otherwise, and broken JSON named *.json.
    assert database_format(write(tmp_path / "p.txt", text_of(profile()))) == GYROFLOW
    assert database_format(root / "Sony" / "broken.json") == GYROFLOW
    assert database_format([root, root / "GoPro"]) == GYROFLOW
    xml = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.01"/>'))
    assert database_format(xml) == LENSFUN
    assert database_format(xml.parent) == LENSFUN
    assert database_format(bundled_db) == LENSFUN
    assert database_format(None) == LENSFUN
    # Whatever else is given as a file is read as XML, as it always was.
    assert database_format(write(tmp_path / "notes.txt", "notes")) == LENSFUN
    assert database_format(write(tmp_path / "x.xml", '{"not": "xml"}')) == LENSFUN


def test_a_directory_with_lensfun_xml_is_lensfun_whatever_json_it_holds(tmp_path, write_xml):
    xml = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.01"/>'))
    write(xml.parent / "profile.json", text_of(profile()))
    assert database_format(xml.parent) == LENSFUN
    assert [name for _, name in expand(xml.parent)] == ["test.xml"]


def test_lensfun_and_gyroflow_given_together_are_refused_in_one_line(tmp_path, write_xml):
    root = make_tree(tmp_path / "lens_profiles")
    profile_file = root / "GoPro" / "GoPro_HERO.json"
    xml = write_xml(lens_xml('<distortion model="poly3" focal="10" k1="-0.01"/>'))
    for given, lensfun, gyro in (
        ([xml.parent, root], xml.parent, root),
        ([root, xml], xml, root),
        ([xml, profile_file], xml, profile_file),
    ):
        with pytest.raises(LoadError) as error:
            database_format(given)
        assert str(error.value) == (
            f"{lensfun} is a Lensfun database and {gyro} Gyroflow lens profiles: "
            "give one kind of database at a time"
        )
        with pytest.raises(LoadError) as error:
            expand(given)
        assert "give one kind of database at a time" in str(error.value)


def test_a_directory_of_neither_is_refused_as_before_or_says_its_json_is_not_profiles(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(LoadError) as error:
        database_format(tmp_path / "empty")
    assert str(error.value) == (
        f"{tmp_path / 'empty'}: directory holds no *.xml files "
        "(give a Lensfun database directory, a Lensfun checkout, or XML files)"
    )
    write(tmp_path / "presets" / "a.json", '{"name": "a preset"}')
    with pytest.raises(LoadError) as error:
        database_format(tmp_path / "presets")
    assert str(error.value) == (
        f"{tmp_path / 'presets'}: directory holds no *.xml files (and its *.json files are not "
        "Gyroflow lens profiles: give a Lensfun database directory, a Lensfun checkout, XML "
        "files or Gyroflow lens profiles)"
    )


def test_read_gyroflow_refuses_a_lensfun_database_and_a_missing_path(tmp_path, bundled_db):
    with pytest.raises(LoadError, match="a Lensfun database, not Gyroflow lens profiles"):
        read_gyroflow(bundled_db)
    with pytest.raises(LoadError, match="no such file or directory"):
        read_gyroflow(tmp_path / "missing")
    with pytest.raises(LoadError, match="no path given"):
        read_gyroflow([])


def run(*arguments: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "lensaudit", *arguments], capture_output=True, text=True, check=False
    )


def test_every_command_refuses_gyroflow_profiles_in_one_line_naming_how_many(tmp_path):
    root = make_tree(tmp_path / "lens_profiles")
    for command in ("scan", "check", "report"):
        arguments = [command, str(root)] + (
            ["-o", str(tmp_path / "out")] if command == "report" else []
        )
        done = run(*arguments)
        assert done.returncode == 2, done.stderr
        assert done.stderr == (
            f"lensaudit: error: {root}: Gyroflow lens profiles (6 files); lensaudit's commands "
            "read Lensfun databases (lensaudit.read.read_gyroflow reads Gyroflow profiles)\n"
        )


def test_the_commands_refuse_mixed_input_in_one_line(tmp_path, bundled_db):
    root = make_tree(tmp_path / "lens_profiles")
    done = run("scan", str(bundled_db), str(root))
    assert done.returncode == 2
    assert done.stderr == (
        f"lensaudit: error: {bundled_db} is a Lensfun database and {root} Gyroflow lens "
        "profiles: give one kind of database at a time\n"
    )


# ---------------------------------------------------------------------------
# Gyroflow's own database
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def real_tree(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Gyroflow's lens_profiles, unpacked from the shared tarball."""
    if not TARBALL.is_file():
        pytest.skip(f"Gyroflow's lens profiles are not here ({TARBALL}): a clone without ../shared")
    target = tmp_path_factory.mktemp("gyroflow")
    with tarfile.open(TARBALL) as archive:
        archive.extractall(target, filter="data")
    return target / "lens_profiles"


def plain_reason(text: str) -> str:
    """Why a profile cannot be audited ("ok" if it can), by plain json alone."""

    def refuse(literal: str) -> None:
        raise ValueError(literal)

    try:
        value = json.loads(text, parse_constant=refuse)
    except ValueError:
        return "json_error"
    fisheye, dimension = value["fisheye_params"], value["calib_dimension"]
    matrix, coefficients = fisheye["camera_matrix"], fisheye["distortion_coeffs"]
    numbers = [x for row in matrix for x in row] + coefficients
    if len(matrix) != 3 or len(coefficients) != 4 or not all(map(math.isfinite, numbers)):
        return "bad_value"
    if not (matrix[0][0] > 0 and matrix[1][1] > 0 and dimension["w"] > 0 and dimension["h"] > 0):
        return "bad_value"
    return "ok"


def test_every_json_file_of_gyroflows_tree_is_a_profile_and_nothing_else_is_read(real_tree):
    walked = sorted(
        os.path.relpath(os.path.join(directory, name), real_tree)
        for directory, _, names in os.walk(real_tree)
        for name in names
        if name.endswith(".json")
    )
    assert len(walked) == REAL_PROFILES
    assert [name for _, name in gyroflow_files(real_tree)] == walked
    assert database_format(real_tree) == GYROFLOW


def test_gyroflows_profiles_usable_and_not_by_reason_as_plain_json_counts_them(real_tree):
    found = read_gyroflow(real_tree)
    plain = {
        os.path.relpath(path, real_tree): plain_reason(path.read_text(encoding="utf-8"))
        for path in real_tree.rglob("*.json")
    }
    assert Counter(p.status for p in found) == Counter(plain.values())
    assert Counter(plain.values()) == Counter({"ok": 9779, "bad_value": 31})
    assert {p.file: p.status for p in found} == plain


def test_gyroflows_profiles_each_on_the_line_of_their_coefficients(real_tree):
    for record in read_gyroflow(real_tree):
        text = (real_tree / record.file).read_text(encoding="utf-8")
        assert record.line == key_line(text, "distortion_coeffs", after="fisheye_params")
        if record.status != "ok":
            line = key_line(text, "camera_matrix", after="fisheye_params")
            assert record.message.startswith(f"{record.file}:{line}: camera_matrix focal length")


def test_gyroflows_profiles_through_the_fast_path_as_field_by_field(real_tree):
    for record in read_gyroflow(real_tree):
        text = (real_tree / record.file).read_text(encoding="utf-8")
        checked = gyroflow._Fields(text, record.file).profile(json.loads(text))
        assert repr(record) == repr(checked)
