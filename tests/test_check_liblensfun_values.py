"""`lensaudit check` says what Lensfun master's liblensfun does with a file whose
lens, calibration, camera or mount definition holds a value liblensfun's
``Check()`` refuses (``libs/lensfun/lens.cpp``, ``camera.cpp``, ``mount.cpp``,
called at the end tag by ``_xml_end_element`` in ``database.cpp``): the whole
file is refused from that definition on, and every lens from there on is lost.

Each case mutates one definition (the second lens, camera or top-level mount
of its file where there is one) of a small hand-made file and of real files of
the bundled database, and compares check's verdict -- a ``liblensfun-refuses``
finding or none, and the lenses it says are lost -- with liblensfun master's
own, loaded through ctypes: refused or not, and the file's lenses it does not
hold. The table also says, from reading liblensfun's source, whether
liblensfun refuses the mutation; the test holds that too, so that a mutation
that missed its mark shows.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from pathlib import Path

import pytest

import liblensfun_load
import liblensfun_master
from lensaudit.check import LIBLENSFUN_REFUSES, check

HAND_MADE = b"""<lensdatabase version="2">
<mount>
  <name>M</name>
  <compat>N</compat>
</mount>
<mount>
  <name>P</name>
  <compat>M</compat>
</mount>
<camera>
  <maker>A</maker>
  <model>Cam 1</model>
  <mount>M</mount>
  <cropfactor>1.5</cropfactor>
</camera>
<camera>
  <maker>A</maker>
  <model>Cam 2</model>
  <mount>P</mount>
  <cropfactor>1</cropfactor>
</camera>
<lens>
  <maker>A</maker>
  <model>One</model>
  <mount>M</mount>
  <cropfactor>1</cropfactor>
  <calibration>
    <distortion model="poly3" focal="50" k1="0.01"/>
  </calibration>
</lens>
<lens>
  <maker>A</maker>
  <model>Two</model>
  <mount>M</mount>
  <cropfactor>1</cropfactor>
  <calibration>
    <distortion model="poly3" focal="50" k1="0.01"/>
  </calibration>
</lens>
<lens>
  <maker>A</maker>
  <model>Three</model>
  <mount>P</mount>
  <cropfactor>1</cropfactor>
  <calibration>
    <distortion model="poly3" focal="50" k1="0.01"/>
  </calibration>
</lens>
</lensdatabase>
"""

#: Real files of the bundled database that liblensfun master loads whole, with
#: more than one lens, and cameras and top-level mounts.
REAL_FILES = ("contax.xml", "6x6.xml", "generic.xml", "mil-leica.xml")

#: Where each kind of definition starts and ends.
_STARTS = {
    "lens": re.compile(rb"<lens>"),
    "camera": re.compile(rb"<camera>"),
    "mount": re.compile(rb"<mount>(?=\s*<name)"),
}


def _text(tag: str) -> re.Pattern[bytes]:
    """Every element ``tag`` of text (with or without attributes), and the
    white space after it."""
    return re.compile(rb"<" + tag.encode() + rb"(?:\s[^>]*)?>[^<]*</" + tag.encode() + rb">\s*")


def removed(tag: str) -> Callable[[bytes], bytes]:
    """The definition without its elements ``tag``."""
    return lambda part: _text(tag).sub(b"", part)


def text_of(tag: str, value: bytes, attributes: bytes = b"") -> Callable[[bytes], bytes]:
    """The definition with one element ``tag`` of text ``value`` (and
    ``attributes``), in place of those it had (or after its start tag)."""
    element = b"<" + tag.encode() + attributes + b">" + value + b"</" + tag.encode() + b">"

    def mutate(part: bytes) -> bytes:
        part = _text(tag).sub(b"", part)
        end = part.index(b">") + 1
        return part[:end] + element + part[end:]

    return mutate


def appended(element: bytes) -> Callable[[bytes], bytes]:
    """The definition with ``element`` added just before its end tag (after
    its calibrations)."""
    return lambda part: part[: part.rindex(b"</")] + element + part[part.rindex(b"</") :]


def empty_elements(tag: str, element: bytes) -> Callable[[bytes], bytes]:
    """The definition with ``element`` in place of its empty elements ``tag``."""
    pattern = re.compile(rb"<" + tag.encode() + rb"\s[^>]*/>\s*")

    def mutate(part: bytes) -> bytes:
        part = pattern.sub(b"", part)
        end = part.index(b">") + 1
        return part[:end] + element + part[end:]

    return mutate


def calibration_attributes(attributes: bytes) -> Callable[[bytes], bytes]:
    """The lens's calibrations with ``attributes`` (a lens without one: with a
    calibration of them, of an entry of no distortion)."""
    start = b"<calibration " + attributes + b">"

    def mutate(part: bytes) -> bytes:
        if b"<calibration>" in part:
            return part.replace(b"<calibration>", start)
        return appended(start + b'<distortion model="none" focal="1"/></calibration>')(part)

    return mutate


def lens_type(name: bytes) -> Callable[[bytes], bytes]:
    return text_of("type", name)


# (kind, mutation, whether liblensfun refuses it, by its source)
CASES: dict[str, tuple[str, Callable[[bytes], bytes], bool]] = {
    # lfLens::Check: CropFactor <= 0, of the lens and of its calibration set.
    "lens crop factor 0": ("lens", text_of("cropfactor", b"0"), True),
    "lens crop factor -0": ("lens", text_of("cropfactor", b"-0"), True),
    "lens crop factor negative": ("lens", text_of("cropfactor", b"-1.5"), True),
    "lens crop factor -inf": ("lens", text_of("cropfactor", b"-inf"), True),
    "lens crop factor not a number": ("lens", text_of("cropfactor", b"abc"), True),
    "lens crop factor with a comma": ("lens", text_of("cropfactor", b"0,5"), True),
    "lens crop factor hexadecimal 0": ("lens", text_of("cropfactor", b"0x0"), True),
    "lens crop factor 0 in single precision": ("lens", text_of("cropfactor", b"1e-50"), True),
    "lens crop factor 0 after its calibrations": (
        "lens",
        appended(b"<cropfactor>0</cropfactor>"),
        True,
    ),
    "lens crop factor nan": ("lens", text_of("cropfactor", b"nan"), False),
    "lens crop factor inf": ("lens", text_of("cropfactor", b"inf"), False),
    "lens crop factor empty": ("lens", text_of("cropfactor", b""), False),
    "lens crop factor 2": ("lens", text_of("cropfactor", b"2"), False),
    # lfLens::Check: AspectRatio < 1.
    "lens aspect ratio 0": ("lens", text_of("aspect-ratio", b"0"), True),
    "lens aspect ratio 0.5": ("lens", text_of("aspect-ratio", b"0.5"), True),
    "lens aspect ratio 3:4": ("lens", text_of("aspect-ratio", b"3:4"), True),
    "lens aspect ratio negative": ("lens", text_of("aspect-ratio", b"-1.5"), True),
    "lens aspect ratio not a number": ("lens", text_of("aspect-ratio", b"abc"), True),
    "lens aspect ratio below 1 after its calibrations": (
        "lens",
        appended(b"<aspect-ratio>0.5</aspect-ratio>"),
        True,
    ),
    "lens aspect ratio 4:0": ("lens", text_of("aspect-ratio", b"4:0"), False),
    "lens aspect ratio 0:0": ("lens", text_of("aspect-ratio", b"0:0"), False),
    "lens aspect ratio 1": ("lens", text_of("aspect-ratio", b"1"), False),
    # <calibration cropfactor= aspect-ratio=> is not what Check() looks at.
    "calibration crop factor 0": ("lens", calibration_attributes(b'cropfactor="0"'), False),
    "calibration aspect ratio 0.5": (
        "lens",
        calibration_attributes(b'aspect-ratio="0.5"'),
        False,
    ),
    "calibration crop factor not a number": (
        "lens",
        calibration_attributes(b'cropfactor="abc"'),
        False,
    ),
    # lfLens::Check: no Model, no mount.
    "lens without model": ("lens", removed("model"), True),
    "lens with an empty model": ("lens", text_of("model", b""), True),
    "lens with a blank model": ("lens", text_of("model", b" \n "), True),
    "lens without mount": ("lens", removed("mount"), True),
    "lens with an empty mount": ("lens", text_of("mount", b""), True),
    "lens without maker": ("lens", removed("maker"), False),
    "lens with a translated model only": ("lens", text_of("model", b"X", b' lang="de"'), False),
    # lfLens::Check: MinFocal > MaxFocal, MinAperture > MaxAperture (set or guessed).
    "lens focal min above max": (
        "lens",
        empty_elements("focal", b'<focal min="50" max="20"/>'),
        True,
    ),
    "lens negative focal lengths descending": (
        "lens",
        empty_elements("focal", b'<focal min="-10" max="-20"/>'),
        True,
    ),
    "lens negative focal max alone": ("lens", empty_elements("focal", b'<focal max="-5"/>'), True),
    "lens negative focal lengths ascending": (
        "lens",
        empty_elements("focal", b'<focal min="-20" max="-10"/>'),
        False,
    ),
    "lens negative focal value": ("lens", empty_elements("focal", b'<focal value="-5"/>'), False),
    "lens focal nan": ("lens", empty_elements("focal", b'<focal min="nan" max="10"/>'), False),
    "lens aperture min above max": (
        "lens",
        empty_elements("aperture", b'<aperture min="8" max="2"/>'),
        True,
    ),
    "lens negative apertures descending": (
        "lens",
        empty_elements("aperture", b'<aperture min="-1" max="-2"/>'),
        True,
    ),
    "lens aperture max 0": (
        "lens",
        empty_elements("aperture", b'<aperture min="8" max="0"/>'),
        False,
    ),
    # Not Check(): a <type> liblensfun does not know stops it at its text.
    "lens type unknown": ("lens", lens_type(b"fish-eye"), True),
    "lens type in capitals": ("lens", lens_type(b" FISHEYE "), False),
    # lfCamera::Check: no Maker, Model or Mount, CropFactor <= 0 (or none).
    "camera without maker": ("camera", removed("maker"), True),
    "camera without model": ("camera", removed("model"), True),
    "camera without mount": ("camera", removed("mount"), True),
    "camera with an empty mount": ("camera", text_of("mount", b" "), True),
    "camera without crop factor": ("camera", removed("cropfactor"), True),
    "camera crop factor 0": ("camera", text_of("cropfactor", b"0"), True),
    "camera crop factor negative": ("camera", text_of("cropfactor", b"-1"), True),
    "camera crop factor not a number": ("camera", text_of("cropfactor", b"abc"), True),
    "camera crop factor 0 in single precision": (
        "camera",
        text_of("cropfactor", b"1e-50"),
        True,
    ),
    "camera crop factor nan": ("camera", text_of("cropfactor", b"nan"), False),
    "camera with a translated model only": (
        "camera",
        text_of("model", b"X", b' lang="de"'),
        False,
    ),
    # lfMount::Check: no Name.
    "mount without name": ("mount", removed("name"), True),
    "mount with an empty name": ("mount", text_of("name", b""), True),
    "mount with a translated name only": ("mount", text_of("name", b"X", b' lang="de"'), False),
    "mount without compat": ("mount", removed("compat"), False),
}


def bundled_files() -> Path:
    lensfunpy = pytest.importorskip("lensfunpy")
    return Path(os.path.dirname(lensfunpy.__file__)) / "db_files"


def original(file: str) -> bytes:
    return HAND_MADE if file == "hand-made" else (bundled_files() / file).read_bytes()


def mutated(data: bytes, kind: str, mutate: Callable[[bytes], bytes]) -> bytes:
    """``data`` with the second definition of ``kind`` (the first, where it has
    one only) mutated."""
    starts = [found.start() for found in _STARTS[kind].finditer(data)]
    assert starts, f"no <{kind}> to mutate"
    start = starts[1] if len(starts) > 1 else starts[0]
    end_tag = b"</" + kind.encode() + b">"
    end = data.index(end_tag, start) + len(end_tag)
    return data[:start] + mutate(data[start:end]) + data[end:]


def liblensfun_lost(data: bytes, lenses_in_file: int) -> int | None:
    """The lenses of the file liblensfun does not hold, None where it loads it whole."""
    result, held = liblensfun_load.load_and_lenses(data)
    return None if result.ok else lenses_in_file - held


def check_lost(path: Path) -> int | None:
    """The lenses check says liblensfun loses, None where it reports no refusal."""
    findings = [f for f in check([path]).findings if f.code == LIBLENSFUN_REFUSES]
    if not findings:
        return None
    assert len(findings) == 1, findings
    found = re.search(r"; (\d+) lens(?:es)? from there on (?:is|are) lost", findings[0].message)
    assert found is not None, findings[0].message
    return int(found.group(1))


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("file", ["hand-made", *REAL_FILES])
def test_check_says_liblensfun_refuses_the_file_and_the_lenses_lost(tmp_path, file, case):
    liblensfun_master.library()
    data = original(file)
    whole, lenses_in_file = liblensfun_load.load_and_lenses(data)
    assert whole.ok, whole.warnings  # the file before the mutation loads whole
    kind, mutate, refused = CASES[case]
    changed = mutated(data, kind, mutate)
    assert changed != data
    expected = liblensfun_lost(changed, lenses_in_file)
    assert (expected is not None) == refused, liblensfun_load.load_and_lenses(changed)[0]
    path = tmp_path / file
    path.write_bytes(changed)
    assert check_lost(path) == expected


@pytest.mark.parametrize(
    "entry",
    [
        b'<distortion model="poly3" focal="50" k1="0.01"/>',
        b'<vignetting model="pa" focal="50" aperture="2" distance="10" k1="-0.1"/>',
        b'<tca model="poly3" focal="50" vr="1.0002" vb="0.9997"/>',
    ],
    ids=["distortion", "vignetting", "tca"],
)
def test_an_entry_outside_a_lens_is_no_lens_and_the_file_refused(tmp_path, entry):
    # liblensfun: "Inappropriate context"; the entry's own finding is no-lens.
    liblensfun_master.library()
    at = HAND_MADE.index(b"<lens>", HAND_MADE.index(b"<model>One"))
    data = HAND_MADE[:at] + entry + b"\n" + HAND_MADE[at:]
    path = tmp_path / "test.xml"
    path.write_bytes(data)
    codes = {f.code for f in check([path]).findings}
    assert "no-lens" in codes
    assert check_lost(path) == liblensfun_lost(data, 3) == 2
