"""The liblensfun_master harness against the Lensfun database lensfunpy bundles.

lensfunpy bundles the database of Lensfun's 0.3 series, where a few lenses still
give their real focal length as a <real-focal-length> element. Lensfun master
dropped that element in 2016 (the real-focal attribute replaces it) and refuses
a file that has one as an unknown element: every other file loads.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from lxml import etree

from liblensfun_master import interpolate_distortion, lenses, library, load_result


@pytest.fixture(scope="module", autouse=True)
def liblensfun():
    """Lensfun master's liblensfun; skips the module where it cannot be built."""
    return library()


@pytest.fixture(scope="module")
def bundled_files() -> list[Path]:
    """The XML files of lensfunpy's bundled database."""
    from lensaudit.read.paths import bundled_database_path

    directory = bundled_database_path()
    files = sorted(directory.glob("*.xml"))
    assert files, f"no database files in {directory}"
    return files


def parsed(path: Path) -> etree._Element:
    """A database file's root element, read by lxml."""
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)
    return etree.parse(str(path), parser).getroot()


def has_real_focal_length_element(path: Path) -> bool:
    """Whether a database file has a <real-focal-length> element (Lensfun 0.3's format)."""
    return next(parsed(path).iter("real-focal-length"), None) is not None


def test_every_bundled_file_loads_in_liblensfun_master_but_those_it_no_longer_reads(
    bundled_files,
):
    outdated = {path.name for path in bundled_files if has_real_focal_length_element(path)}
    refused = {}
    for path in bundled_files:
        result = load_result(path.read_bytes(), path.name)
        if not result.ok:
            refused[path.name] = (result.error, result.warnings)
    assert set(refused) == outdated
    assert len(outdated) < len(bundled_files) / 4
    for error, warnings in refused.values():
        assert error == "LF_WRONG_FORMAT"
        assert "Unknown element <real-focal-length>!" in warnings


@pytest.fixture(scope="module")
def largest_file(bundled_files) -> Path:
    """The bundled file with the most <lens> elements among those without <real-focal-length>."""
    current = [path for path in bundled_files if not has_real_focal_length_element(path)]
    return max(current, key=lambda path: (len(parsed(path).findall("lens")), path.name))


def test_liblensfun_holds_one_lens_for_every_lens_element(largest_file):
    elements = parsed(largest_file).findall("lens")
    held = lenses(largest_file.read_bytes())
    assert len(elements) > 10
    assert len(held) == len(elements)
    # liblensfun keeps the last <model> without a language, less its leading whitespace.
    models = [element.xpath("model[not(@lang)]")[-1].text.lstrip() for element in elements]
    assert [lens["model"] for lens in held] == models


def test_interpolation_at_a_calibrated_focal_length_is_that_calibration(largest_file):
    lens = next(lens for lens in lenses(largest_file.read_bytes()) if lens["distortion"])
    calibration = lens["distortion"][0]
    found = interpolate_distortion(lens, lens["crop_factor"], calibration["focal"])
    assert found == (calibration["model"], calibration["terms"])
