"""`lensaudit plot`: naming an entry (FILE:LINE or a query) and the images written."""

from __future__ import annotations

import struct
import warnings

import pytest
from click.testing import CliRunner

from conftest import lens_xml
from lensaudit.cli import main


def png_size(path):
    """(width, height) from a PNG's IHDR chunk."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


@pytest.fixture
def runner():
    return CliRunner()


@pytest.fixture
def small_db(write_xml):
    return write_xml(
        lens_xml(
            '<distortion model="poly3" focal="10" k1="-0.3"/>',
            '<distortion model="acm" focal="20" k1="0.01"/>',
        )
    )


def test_an_ambiguous_query_lists_the_candidates(runner, tmp_path):
    out = tmp_path / "curve.png"
    result = runner.invoke(
        main, ["plot", "curve", "--lens", "Tokina 11-16", "--focal", "11", "-o", str(out)]
    )
    assert result.exit_code == 2
    lines = result.output.splitlines()
    assert lines[0].startswith("lensaudit: error:") and "match" in lines[0]
    assert any(line.strip().endswith("(slr-tokina.xml:17)") for line in lines[1:])
    assert any(line.strip().endswith("(slr-tokina.xml:39)") for line in lines[1:])
    assert all("11 mm" in line for line in lines[1:])
    assert not out.exists()


def test_a_narrow_query_names_one_entry(runner, tmp_path):
    out = tmp_path / "curve.png"
    result = runner.invoke(
        main,
        ["plot", "curve", "--lens", "Tokina 11-16", "--focal", "11", "--crop", "1", "-o", str(out)],
    )
    assert result.exit_code == 0, result.output
    assert png_size(out) == (700, 600)


def test_file_line_names_an_entry_of_the_bundled_database(runner, tmp_path):
    out = tmp_path / "curve.svg"
    result = runner.invoke(main, ["plot", "curve", "slr-tokina.xml:17", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert out.read_text().lstrip().startswith("<?xml")


def test_file_line_may_be_a_path_to_an_xml_file(runner, small_db, tmp_path):
    out = tmp_path / "warp.png"
    result = runner.invoke(
        main, ["plot", "warp", f"{small_db}:10", "-o", str(out), "--size", "300x200"]
    )
    assert result.exit_code == 0, result.output
    assert png_size(out) == (300, 200)


def test_warp_output_has_the_requested_size(runner, tmp_path):
    out = tmp_path / "warp.png"
    result = runner.invoke(main, ["plot", "warp", "slr-tokina.xml:17", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert png_size(out) == (1000, 666)


def test_a_line_without_an_entry_is_an_input_error(runner, tmp_path):
    result = runner.invoke(
        main, ["plot", "curve", "slr-tokina.xml:2", "-o", str(tmp_path / "x.png")]
    )
    assert result.exit_code == 2
    assert "no <distortion> entry at slr-tokina.xml:2" in result.output
    assert "Traceback" not in result.output


def test_an_entry_that_was_not_audited_cannot_be_plotted(runner, small_db, tmp_path):
    result = runner.invoke(main, ["plot", "curve", f"{small_db}:11", "-o", str(tmp_path / "x.png")])
    assert result.exit_code == 2 and "unknown_model" in result.output


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["curve", "slr-tokina.xml"], "is not FILE:LINE"),
        (["curve"], "name an entry"),
        (["curve", "slr-tokina.xml:17", "--lens", "Tokina"], "not both"),
        (["curve", "--lens", "no such lens anywhere"], "no audited entry matches"),
        (["warp", "slr-tokina.xml:17", "--size", "big"], "WIDTHxHEIGHT"),
        (["warp", "slr-tokina.xml:17", "--scale", "-1"], "--scale must be"),
        (["map", "--range", "1", "-1"], "MIN < MAX"),
        (["map", "--range", "-1e308", "1e308"], "from -1e300 to 1e300"),
        (["map", "--range", "-inf", "1"], "from -1e300 to 1e300"),
        (["map", "--range", "0", "nan"], "MIN < MAX"),
        (["map", "--k3", "0", "--k3", "1e308"], "--k3 0 1e+308: expected numbers"),
        (["map", "--k3", "nan"], "from -1e300 to 1e300"),
    ],
)
def test_bad_requests_exit_2_with_a_message(runner, tmp_path, arguments, message):
    result = runner.invoke(main, ["plot", *arguments, "-o", str(tmp_path / "x.png")])
    assert result.exit_code == 2
    assert message in result.output and "Traceback" not in result.output


def test_unknown_image_format_is_refused(runner, tmp_path):
    result = runner.invoke(
        main, ["plot", "curve", "slr-tokina.xml:17", "-o", str(tmp_path / "x.bmp")]
    )
    assert result.exit_code == 2 and ".png" in result.output


def test_missing_database_is_an_input_error(runner, tmp_path):
    result = runner.invoke(
        main,
        ["plot", "curve", "x.xml:3", "--db", str(tmp_path / "none"), "-o", str(tmp_path / "x.png")],
    )
    assert result.exit_code == 2 and "no such file" in result.output


def test_a_map_at_the_ends_of_its_range_is_drawn_without_a_warning(runner, tmp_path):
    out = tmp_path / "map.png"
    words = ["plot", "map", "--range", "-1e300", "1e300", "--k3", "-1e300", "--k3", "1e300"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = runner.invoke(main, [*words, "--resolution", "5", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert png_size(out)[0] > 100


def test_map_writes_a_figure(runner, tmp_path):
    out = tmp_path / "map.png"
    result = runner.invoke(
        main, ["plot", "map", "--k3", "0", "--k3", "0.5", "--resolution", "41", "-o", str(out)]
    )
    assert result.exit_code == 0, result.output
    width, height = png_size(out)
    assert width > height > 100
