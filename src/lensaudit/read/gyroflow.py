"""Gyroflow lens profiles: one JSON file's bytes into a plain record.

A Gyroflow lens profile is a JSON object holding ``calib_dimension`` (the
frame the calibration was made at, ``{w, h}`` in pixels) and
``fisheye_params``: ``camera_matrix`` [[fx, 0, cx], [0, fy, cy], [0, 0, 1]],
``distortion_coeffs`` [k1, k2, k3, k4], ``RMS_error`` and
``radial_distortion_limit``. Its model is OpenCV's fisheye model:
theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8), theta
the angle from the optical axis, pixel = f theta_d + c. A profile is
recognised by its content (:func:`is_profile`), never by its name alone.

:func:`read_profile` gives one :class:`Profile` per file, whatever the bytes:
a file that is not UTF-8 or not JSON, JSON that is not a profile, a profile
missing a field the audit uses or holding a value it cannot use (a number
that is not finite, NaN and Infinity included, which Python's json accepts
and JSON does not; a focal length or frame size that is not positive; not
four coefficients) has a status other than ``ok`` and a one-line message
naming the file and line. Nothing here raises on the content.
"""

from __future__ import annotations

import json
import re
from collections import namedtuple

from .records import (
    NAN,
    STATUS_BAD_VALUE,
    STATUS_JSON_ERROR,
    STATUS_MISSING_ATTRIBUTE,
    STATUS_NOT_DATABASE,
    STATUS_OK,
    STATUS_UNKNOWN_MODEL,
    STATUS_UNREADABLE,
)

INF = float("inf")

#: Larger files are not read as profiles: Gyroflow's largest is about 26 kB.
MAX_PROFILE_BYTES = 1 << 20
#: The keys that make a JSON object a Gyroflow lens profile (either one).
PROFILE_KEYS = ("calib_dimension", "fisheye_params")
#: A frame side beyond this many pixels is not a camera's.
MAX_DIMENSION = 1 << 20
#: The coefficients of OpenCV's fisheye model, in order.
COEFFICIENTS = ("k1", "k2", "k3", "k4")
#: ``distortion_model`` values that name OpenCV's fisheye model (null does too).
FISHEYE_MODELS = frozenset({"opencv_fisheye"})

#: The fields of a :class:`Profile`, in order, and the type of each.
PROFILE_FIELDS = {
    "file": "str",
    "line": "int",
    "camera_brand": "str",
    "camera_model": "str",
    "lens_model": "str",
    "camera_setting": "str",
    "name": "str",
    "w": "int",
    "h": "int",
    "fx": "float",
    "fy": "float",
    "cx": "float",
    "cy": "float",
    "k1": "float",
    "k2": "float",
    "k3": "float",
    "k4": "float",
    "official": "bool",
    "digital_lens": "str",
    "asymmetrical": "bool",
    "horizontal_stretch": "float",
    "vertical_stretch": "float",
    "rms_error": "float",
    "radial_distortion_limit": "float",
    "status": "str",
    "message": "str",
}

#: The text fields, as (record field, JSON key): "" where the key is absent or null.
TEXT_FIELDS = (
    ("camera_brand", "camera_brand"),
    ("camera_model", "camera_model"),
    ("lens_model", "lens_model"),
    ("camera_setting", "camera_setting"),
    ("name", "name"),
    ("digital_lens", "digital_lens"),
)

# Which problem a profile is said to have first: the most basic.
_PRIORITY = (
    STATUS_UNREADABLE,
    STATUS_JSON_ERROR,
    STATUS_NOT_DATABASE,
    STATUS_MISSING_ATTRIBUTE,
    STATUS_UNKNOWN_MODEL,
    STATUS_BAD_VALUE,
)
_BOMS = (
    (b"\xef\xbb\xbf", "a UTF-8 byte-order mark"),
    (b"\xff\xfe", "a UTF-16 (or UTF-32) byte-order mark"),
    (b"\xfe\xff", "a UTF-16 byte-order mark"),
    (b"\x00\x00\xfe\xff", "a UTF-32 byte-order mark"),
)
_BOM_STARTS = frozenset(mark[:1] for mark, _ in _BOMS)
# An integer of more digits than Python converts (sys.get_int_max_str_digits).
_LONG_INTEGER = re.compile(r"\d{4301,}")
# Strings, to be blanked out before looking for NaN or Infinity outside them.
_STRING = re.compile(r'"(?:[^"\\\n]|\\.)*"')
_CONSTANT = re.compile(r"-?\b(?:NaN|Infinity)\b")


class Profile(namedtuple("Profile", tuple(PROFILE_FIELDS))):
    """One Gyroflow lens profile file.

    ``file`` is the name it is reported as; ``line`` the line of its
    ``fisheye_params.distortion_coeffs`` (where findings about the model are
    placed), else of its first problem (1 where there is none to name).
    Camera and lens names are as written ("" where absent or null); ``w``,
    ``h`` the calibration's frame in pixels (0 where unusable); ``fx``,
    ``fy``, ``cx``, ``cy`` from the camera matrix and ``k1``..``k4`` the
    fisheye coefficients (NaN where unusable); ``official``,
    ``digital_lens`` (a name such as ``gopro_superview``, "" for none),
    ``asymmetrical`` and the stretch factors (1 where absent) as written;
    ``rms_error`` and ``radial_distortion_limit`` NaN where absent or null.
    ``status`` is ``ok`` or why the profile cannot be audited, ``message``
    one line naming the file and line of each problem ("" when ``ok``).
    """

    __slots__ = ()


#: A profile with nothing read yet: every field at its default.
_EMPTY = Profile(
    "",
    1,
    "",
    "",
    "",
    "",
    "",
    0,
    0,
    *(NAN,) * 8,
    False,
    "",
    False,
    1.0,
    1.0,
    NAN,
    NAN,
    STATUS_OK,
    "",
)


def refused(name: str, status: str, line: int, message: str) -> Profile:
    """The record of a file that gives no profile: ``status`` and why, at
    ``line`` (0 for the file as a whole)."""
    where = f"{name}:{line}" if line else name
    return _EMPTY._replace(file=name, line=line, status=status, message=f"{where}: {message}")


def is_profile(data: bytes) -> bool:
    """Whether ``data`` is a Gyroflow lens profile by content: a JSON object
    (UTF-8, no larger than :data:`MAX_PROFILE_BYTES`) holding
    ``calib_dimension`` or ``fisheye_params``, usable or not."""
    if len(data) > MAX_PROFILE_BYTES or not data.lstrip()[:1] == b"{":
        return False
    try:
        value = json.loads(data.decode("utf-8"))
    except (ValueError, RecursionError):
        return False
    return isinstance(value, dict) and any(key in value for key in PROFILE_KEYS)


def read_profile(data: bytes, name: str) -> Profile:
    """The :class:`Profile` of one file's bytes, shown as ``name``."""
    parsed = _parsed(data, name)
    if isinstance(parsed, Profile):
        return parsed
    text, value, constants = parsed
    if not isinstance(value, dict):
        return refused(
            name,
            STATUS_NOT_DATABASE,
            1,
            f"not a Gyroflow lens profile: the JSON is {_kind(value)}, not an object",
        )
    if "calib_dimension" not in value and "fisheye_params" not in value:  # PROFILE_KEYS
        return refused(
            name,
            STATUS_NOT_DATABASE,
            1,
            "not a Gyroflow lens profile: no calib_dimension or fisheye_params",
        )
    if not constants:
        clean = _clean(value, text, name)
        if clean is not None:
            return clean
    return _Fields(text, name).profile(value, constants)


_FLOAT = frozenset({float})
_TEXT = frozenset({str, type(None)})
_FLAG = frozenset({bool, type(None)})
_MEASURE = frozenset({float, type(None)})


def _clean(value: dict, text: str, name: str) -> Profile | None:
    """The profile of a JSON object (without NaN or Infinity) with nothing
    wrong or unusual, made at once, as :class:`_Fields` makes it; None for
    anything else (a value not of the type the data has), which
    :class:`_Fields` then checks field by field. Nearly every real profile
    is made here: checking each field alone costs as much again as parsing."""
    fisheye = value.get("fisheye_params")
    dimension = value.get("calib_dimension")
    if type(fisheye) is not dict or type(dimension) is not dict:
        return None
    try:
        (fx, skew, cx), (low, fy, cy), (zero, nought, one) = fisheye.get("camera_matrix")
        k1, k2, k3, k4 = fisheye.get("distortion_coeffs")
    except (TypeError, ValueError):
        return None
    # Each a float: what is unpacked from anything but lists of numbers is not.
    numbers = (fx, skew, cx, low, fy, cy, zero, nought, one, k1, k2, k3, k4)
    if set(map(type, numbers)) != _FLOAT or type(fisheye["camera_matrix"]) is not list:
        return None
    total = sum(numbers)
    if total - total != 0 or not (fx > 0 and fy > 0) or skew or low or zero or nought or one != 1:
        return None
    if type(fisheye["distortion_coeffs"]) is not list:
        return None
    w, h = dimension.get("w"), dimension.get("h")
    if (
        type(w) is not int
        or type(h) is not int
        or not (0 < w <= MAX_DIMENSION and 0 < h <= MAX_DIMENSION)
    ):
        return None
    rest = _clean_rest(value, fisheye)
    if rest is None:
        return None
    line = _key_line(text, "distortion_coeffs", text.find('"fisheye_params"')) or 1
    return tuple.__new__(Profile, (name, line, *rest[:5], w, h, fx, fy, cx, cy, k1, k2, k3, k4,
                                   *rest[5:], STATUS_OK, ""))  # fmt: skip


def _clean_rest(value: dict, fisheye: dict) -> tuple | None:
    """The names, flags, stretches, RMS error and limit of a profile, in the
    order of :class:`Profile`, where each is as the data has them (see
    :func:`_clean`); None otherwise."""
    get = value.get
    texts = [get(key) for _, key in TEXT_FIELDS]
    official, asymmetrical = get("official"), get("asymmetrical")
    measures = [get("input_horizontal_stretch"), get("input_vertical_stretch"),
                fisheye.get("RMS_error"), fisheye.get("radial_distortion_limit")]  # fmt: skip
    if (
        not set(map(type, texts)) <= _TEXT
        or not {type(official), type(asymmetrical)} <= _FLAG
        or not set(map(type, measures)) <= _MEASURE
    ):
        return None
    horizontal, vertical, rms, limit = measures
    if (
        not (horizontal is None or 0 < horizontal < INF)
        or not (vertical is None or 0 < vertical < INF)
        or not (rms is None or 0 <= rms < INF)
        or not (limit is None or 0 <= limit < INF)
    ):
        return None
    if (
        get("distortion_model") is not None
        or get("distortion_model_id") not in (None, 0)
        or get("use_opencv_standard") is True
        or get("use_opencv_fisheye") is False
    ):
        return None
    brand, model, lens, setting, profile_name, digital = (text or "" for text in texts)
    return (brand, model, lens, setting, profile_name, official is True, digital,
            asymmetrical is True, 1.0 if horizontal is None else horizontal,
            1.0 if vertical is None else vertical, NAN if rms is None else rms,
            NAN if limit is None else limit)  # fmt: skip


def _key_line(text: str, key: str, start: int = 0) -> int:
    """The line of ``"key":`` in JSON text from ``start`` on, 0 where there is none."""
    quoted = f'"{key}"'
    found = text.find(quoted, max(start, 0))
    while found >= 0:
        after = found + len(quoted)
        while text[after : after + 1] in (" ", "\t", "\n", "\r"):
            after += 1
        if text[after : after + 1] == ":":
            return text.count("\n", 0, found) + 1
        found = text.find(quoted, found + 1)
    return 0


class _Constant(Exception):
    """A NaN or Infinity, which Python's json reads and JSON does not have."""


def _refuse_constant(literal: str) -> float:
    raise _Constant(literal)


# Python's json with NaN and Infinity refused: costs nothing where there is none.
_DECODER = json.JSONDecoder(parse_constant=_refuse_constant)


def _parsed(data: bytes, name: str) -> Profile | tuple[str, object, bool]:
    """(text, JSON value, whether it holds NaN or Infinity) of a file's bytes,
    or the record saying why they are not JSON."""
    if len(data) > MAX_PROFILE_BYTES:
        return refused(
            name,
            STATUS_NOT_DATABASE,
            0,
            f"larger than {MAX_PROFILE_BYTES >> 20} MiB, not a Gyroflow lens profile",
        )
    for mark, described in _BOMS if data[:1] in _BOM_STARTS else ():
        if data.startswith(mark):
            return refused(
                name,
                STATUS_JSON_ERROR,
                1,
                f"not valid JSON: begins with {described}; JSON is UTF-8 without one",
            )
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        byte = data[error.start]
        return refused(
            name, STATUS_JSON_ERROR, line, f"not valid JSON: byte 0x{byte:02x} is not UTF-8"
        )
    try:
        try:
            return text, _DECODER.decode(text), False
        except _Constant:
            return text, json.loads(text), True
    except json.JSONDecodeError as error:
        if "\x00" in text:  # UTF-16 or UTF-32 without a byte-order mark
            line = text.count("\n", 0, text.index("\x00")) + 1
            message = "not valid JSON: a NUL byte (UTF-16 or UTF-32?); JSON is UTF-8"
            return refused(name, STATUS_JSON_ERROR, line, message)
        message = f"not valid JSON: {error.msg} (column {error.colno})"
        return refused(name, STATUS_JSON_ERROR, error.lineno, message)
    except RecursionError:
        return refused(name, STATUS_JSON_ERROR, 1, "not valid JSON: nested too deeply to read")
    except ValueError:  # Python converts no integer of more than 4300 digits
        match = _LONG_INTEGER.search(text)
        line = text.count("\n", 0, match.start()) + 1 if match else 1
        return refused(name, STATUS_BAD_VALUE, line, "an integer of more than 4300 digits")


def _constant_line(text: str) -> int:
    """The line of the first NaN or Infinity outside a string, or 0 for none."""
    match = _CONSTANT.search(_STRING.sub('""', text))
    return 0 if match is None else match.string.count("\n", 0, match.start()) + 1


def _number(value: object) -> float | str:
    """A JSON number as a finite float, or why it is not one."""
    if type(value) is float:
        if value - value == 0:
            return value
        return "is NaN, which JSON does not allow" if value != value else "is not finite"
    if type(value) is int:
        try:
            return float(value)
        except OverflowError:
            return "is too large for a double"
    return f"is {_kind(value)}, not a number"


def _kind(value: object) -> str:
    """What a JSON value is, for a message."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        shown = value if len(value) <= 20 else value[:20] + "..."
        return f"the string {shown!r}"
    return {dict: "an object", list: "an array"}.get(type(value), repr(value))


class _Fields:
    """The fields of one profile's JSON object, checked one by one; each
    problem kept with its status and the line of its key."""

    def __init__(self, text: str, name: str) -> None:
        self.text = text
        self.name = name
        self.problems: list[tuple[str, int, str]] = []
        self.fisheye_at = 0  # where fisheye_params's value starts in the text

    def line(self, key: str, start: int = 0) -> int:
        """The line of ``"key":`` from ``start`` on (1 where it is not found)."""
        return _key_line(self.text, key, start) or 1

    def problem(self, status: str, key: str, message: str, nested: bool = False) -> None:
        """Keep a problem of ``key`` (a key of fisheye_params where ``nested``)."""
        line = self.line(key, self.fisheye_at if nested else 0)
        self.problems.append((status, line, message))

    def profile(self, value: dict, constants: bool = False) -> Profile:
        """The :class:`Profile` of a JSON object that holds a profile key;
        ``constants`` where its text holds NaN or Infinity."""
        fields: dict[str, object] = {"file": self.name}
        for field, key in TEXT_FIELDS:
            fields[field] = self.text_field(value, key)
        for field, key in (("official", "official"), ("asymmetrical", "asymmetrical")):
            fields[field] = self.flag(value, key)
        for field, key in (
            ("horizontal_stretch", "input_horizontal_stretch"),
            ("vertical_stretch", "input_vertical_stretch"),
        ):
            fields[field] = self.measure(value, key, 1.0, "a positive number", positive=True)
        self.model(value)
        fields["w"], fields["h"] = self.dimension(value)
        fields.update(self.fisheye(value))
        constant = _constant_line(self.text) if constants else 0
        if constant and not self.problems:
            # In a field the audit does not use: still not JSON.
            self.problems.append(
                (STATUS_BAD_VALUE, constant, "NaN or Infinity is not a JSON number")
            )
        coefficients_line = (
            self.line("distortion_coeffs", self.fisheye_at) if self.fisheye_at else 0
        )
        status, line, message = self.verdict()
        fields["line"] = coefficients_line or line
        return _EMPTY._replace(**fields, status=status, message=message)

    def verdict(self) -> tuple[str, int, str]:
        """(status, line, message) of the problems kept: the most basic first,
        every one in the message, in the order of their lines."""
        if not self.problems:
            return STATUS_OK, 1, ""
        status, line, _ = min(self.problems, key=lambda p: (_PRIORITY.index(p[0]), p[1]))
        ordered = sorted(self.problems, key=lambda p: p[1])
        parts = [f"{self.name}:{ordered[0][1]}: {ordered[0][2]}"]
        parts += [f"line {problem_line}: {text}" for _, problem_line, text in ordered[1:]]
        return status, line, "; ".join(parts)

    def text_field(self, value: dict, key: str) -> str:
        """A text field: "" where absent or null."""
        found = value.get(key)
        if found is None or isinstance(found, str):
            return found or ""
        self.problem(STATUS_BAD_VALUE, key, f"{key} is {_kind(found)}, not a string")
        return ""

    def flag(self, value: dict, key: str) -> bool:
        """A true/false field: false where absent or null."""
        found = value.get(key)
        if found is None or isinstance(found, bool):
            return bool(found)
        self.problem(STATUS_BAD_VALUE, key, f"{key} is {_kind(found)}, not true or false")
        return False

    def measure(
        self,
        value: dict,
        key: str,
        default: float,
        wanted: str,
        positive: bool = False,
        nested: bool = False,
    ) -> float:
        """A number field: ``default`` where absent or null, NaN where unusable;
        ``positive`` (else not negative) as ``wanted`` says."""
        found = value.get(key)
        if found is None:
            return default
        number = _number(found)
        if isinstance(number, str):
            self.problem(STATUS_BAD_VALUE, key, f"{key} {number}", nested)
            return NAN
        if number < 0 or (positive and number == 0):
            self.problem(STATUS_BAD_VALUE, key, f"{key} {found!r} is not {wanted}", nested)
            return NAN
        return number

    def model(self, value: dict) -> None:
        """Keep a problem where the profile names a model other than OpenCV's fisheye."""
        named = value.get("distortion_model")
        if named is not None and named not in FISHEYE_MODELS:
            self.problem(
                STATUS_UNKNOWN_MODEL,
                "distortion_model",
                f"distortion_model {_kind(named)} is not OpenCV's fisheye model",
            )
        identifier = value.get("distortion_model_id")
        if identifier is not None and identifier != 0:
            self.problem(
                STATUS_UNKNOWN_MODEL,
                "distortion_model_id",
                f"distortion_model_id {_kind(identifier)} is not OpenCV's fisheye model (0)",
            )
        if value.get("use_opencv_standard") is True or value.get("use_opencv_fisheye") is False:
            key = (
                "use_opencv_standard" if value.get("use_opencv_standard") else "use_opencv_fisheye"
            )
            self.problem(
                STATUS_UNKNOWN_MODEL, key, f"{key} says the profile is not OpenCV's fisheye model"
            )

    def dimension(self, value: dict) -> tuple[int, int]:
        """(w, h) of ``calib_dimension``, (0, 0) where unusable."""
        found = value.get("calib_dimension")
        if "calib_dimension" not in value:
            self.problem(STATUS_MISSING_ATTRIBUTE, "fisheye_params", "no calib_dimension")
            return 0, 0
        if not isinstance(found, dict):
            self.problem(
                STATUS_BAD_VALUE,
                "calib_dimension",
                f"calib_dimension is {_kind(found)}, not an object {{w, h}}",
            )
            return 0, 0
        sides = []
        for side in ("w", "h"):
            size = found.get(side)
            if side not in found:
                self.problem(
                    STATUS_MISSING_ATTRIBUTE, "calib_dimension", f"calib_dimension has no {side}"
                )
            elif type(size) is not int or not 0 < size <= MAX_DIMENSION:
                self.problem(
                    STATUS_BAD_VALUE,
                    "calib_dimension",
                    f"calib_dimension {side} {_kind(size) if type(size) is not int else size} "
                    "is not a positive whole number of pixels",
                )
            else:
                sides.append(size)
                continue
            sides.append(0)
        return sides[0], sides[1]

    def fisheye(self, value: dict) -> dict[str, float]:
        """The camera matrix, coefficients, RMS error and radial distortion limit."""
        if "fisheye_params" not in value:
            self.problem(STATUS_MISSING_ATTRIBUTE, "calib_dimension", "no fisheye_params")
            return {}
        found = value["fisheye_params"]
        self.fisheye_at = max(self.text.find('"fisheye_params"'), 0)
        if not isinstance(found, dict):
            self.problem(
                STATUS_BAD_VALUE,
                "fisheye_params",
                f"fisheye_params is {_kind(found)}, not an object",
            )
            return {}
        fields = {**self.matrix(found), **self.coefficients(found)}
        fields["rms_error"] = self.measure(found, "RMS_error", NAN, "a number >= 0", nested=True)
        fields["radial_distortion_limit"] = self.measure(
            found, "radial_distortion_limit", NAN, "a number >= 0", nested=True
        )
        return fields

    def matrix(self, fisheye: dict) -> dict[str, float]:
        """fx, fy, cx, cy of ``camera_matrix`` [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]."""
        key = "camera_matrix"
        if key not in fisheye:
            self.problem(STATUS_MISSING_ATTRIBUTE, "fisheye_params", f"fisheye_params has no {key}")
            return {}
        rows = fisheye[key]
        if not (
            isinstance(rows, list)
            and len(rows) == 3
            and all(isinstance(row, list) and len(row) == 3 for row in rows)
        ):
            self.problem(STATUS_BAD_VALUE, key, f"{key} is not 3 rows of 3 numbers", True)
            return {}
        numbers = [_number(item) for row in rows for item in row]
        for index, number in enumerate(numbers):
            if isinstance(number, str):
                self.problem(
                    STATUS_BAD_VALUE, key, f"{key}[{index // 3}][{index % 3}] {number}", True
                )
        if any(isinstance(number, str) for number in numbers):
            return {}
        fx, skew, cx, low, fy, cy, *last = numbers
        if skew != 0 or low != 0 or last != [0.0, 0.0, 1.0]:
            self.problem(
                STATUS_BAD_VALUE,
                key,
                f"{key} is not of the form [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]",
                True,
            )
        fields = {"fx": fx, "fy": fy, "cx": cx, "cy": cy}
        for focal in ("fx", "fy"):
            if not fields[focal] > 0:
                self.problem(
                    STATUS_BAD_VALUE,
                    key,
                    f"{key} focal length {focal} {fields[focal]!r} is not positive",
                    True,
                )
                fields[focal] = NAN
        return fields

    def coefficients(self, fisheye: dict) -> dict[str, float]:
        """k1..k4 of ``distortion_coeffs``: exactly four numbers."""
        key = "distortion_coeffs"
        if key not in fisheye:
            self.problem(STATUS_MISSING_ATTRIBUTE, "fisheye_params", f"fisheye_params has no {key}")
            return {}
        found = fisheye[key]
        if not isinstance(found, list):
            self.problem(STATUS_BAD_VALUE, key, f"{key} is {_kind(found)}, not 4 numbers", True)
            return {}
        if len(found) != len(COEFFICIENTS):
            self.problem(
                STATUS_BAD_VALUE,
                key,
                f"{key} holds {len(found)} numbers, not 4 (k1, k2, k3, k4)",
                True,
            )
            return {}
        fields = {}
        for coefficient, item in zip(COEFFICIENTS, found, strict=True):
            number = _number(item)
            if isinstance(number, str):
                self.problem(STATUS_BAD_VALUE, key, f"{key} {coefficient} {number}", True)
                number = NAN
            fields[coefficient] = number
        return fields
