"""Each fold that check reports names the `lensaudit fix` command that refits it,
and that command, run as written (in the directory check ran in), selects
exactly that entry, in the file check read: never another database's."""

from __future__ import annotations

import json
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from lensaudit import check
from lensaudit.cli import main
from lensaudit.read import DistortionEntry


def test_every_fold_in_the_image_names_a_fix_command_that_selects_it(bundled_db):
    checked = CliRunner().invoke(main, ["check", str(bundled_db), "--format", "json"])
    folds = [f for f in json.loads(checked.output)["findings"] if f["code"] == "fold-in-image"]
    assert folds
    for finding in folds:
        command = _suggested(finding["message"])
        arguments = _with_json(shlex.split(command)[1:])
        assert arguments[-1] == finding["file"]
        fixed = CliRunner().invoke(main, arguments)
        assert fixed.exit_code == 0, fixed.output
        selected = [(e["file"], e["line"]) for e in json.loads(fixed.output)["entries"]]
        assert selected == [(finding["file"], finding["line"])], command


@pytest.mark.parametrize("name", ['Odd "$HOME" `x` \\ lens', "Plain 14-42mm f/3.5-5.6", "It's"])
def test_the_suggested_lens_name_survives_a_posix_shell(name):
    entry = DistortionEntry("x.xml", 1, "Maker", name, (), "rectilinear", 1.0, 1.5, "ptlens", 11.0)
    command = re.search(
        r"`lensaudit fix --lens (.+) --focal 11 -- x.xml` refits it$", check.fix_suggestion(entry)
    )
    if shutil.which("bash") is None:
        pytest.skip("no bash to judge the quoting")
    echoed = subprocess.run(
        ["bash", "-c", f"printf %s {command.group(1)}"], capture_output=True, text=True, check=True
    ).stdout
    assert echoed == name


#: Lens names a shell or a one-line message could mangle.
AWKWARD = [
    "Sigma 17-35mm F2.8-4 EX DG  Aspherical HSM",  # two spaces (slr-sigma.xml)
    'It\'s a "quoted" lens',
    "Price $HOME ${PATH} $(id)",
    "Back `id` tick",
    "-leading dash",
    "Ünïcödé 鏡頭 12mm",
    "Tab\there and   many spaces",
    '=HYPERLINK("http://x") ; rm -rf / #',
    "A very long name " + "that goes on " * 12 + "and on",
    "Bidi \u202eevil\u202c name",
]


def _awkward_database(tmp_path):
    lenses = "".join(
        f"""    <lens>
        <maker>Odd</maker>
        <model>{name.replace("&", "&amp;").replace("<", "&lt;")}</model>
        <mount>Odd Mount</mount>
        <cropfactor>1.5</cropfactor>
        <calibration>
            <distortion model="ptlens" focal="{11 + index}" a="-0.024" b="-0.002" c="0.005"/>
        </calibration>
    </lens>
"""
        for index, name in enumerate(AWKWARD)
    )
    path = tmp_path / "db" / "odd.xml"
    path.parent.mkdir()
    path.write_text(f'<lensdatabase version="2">\n{lenses}</lensdatabase>\n', encoding="utf-8")
    return path


def _with_json(arguments: list[str]) -> list[str]:
    """A suggested command's arguments with ``-f json`` before its ``--``."""
    end = arguments.index("--")
    return [*arguments[:end], "-f", "json", *arguments[end:]]


def _suggested(message: str) -> str:
    """The command a finding's message ends with (names may hold backticks)."""
    start = message.rindex("`lensaudit fix ")
    end = message.rindex("` refits it")
    return message[start + 1 : end]


def _check(path, output_format: str) -> dict[int, str]:
    """The fold findings' messages of ``lensaudit check`` as a process, by line."""
    checked = subprocess.run(
        [sys.executable, "-m", "lensaudit", "check", str(path), "--format", output_format],
        capture_output=True, text=True, encoding="utf-8", check=False,
    )  # fmt: skip
    assert checked.returncode == 1, checked.stderr
    if output_format == "json":
        findings = json.loads(checked.stdout)["findings"]
        return {f["line"]: f["message"] for f in findings if f["code"] == "fold-in-image"}
    found = re.findall(r"odd\.xml:(\d+): error \[fold-in-image\] (.*)", checked.stdout)
    return {int(line): message for line, message in found}


def test_each_suggested_command_pasted_into_a_shell_selects_its_entry(tmp_path):
    path = _awkward_database(tmp_path)
    commands = {line: _suggested(m) for line, m in _check(path.parent, "text").items()}
    assert len(commands) == len(AWKWARD)
    assert commands == {line: _suggested(m) for line, m in _check(path.parent, "json").items()}
    for line, command in commands.items():
        words = shlex.split(command)
        assert words[:2] == ["lensaudit", "fix"], command
        fixed = subprocess.run(
            [sys.executable, "-m", "lensaudit", *_with_json(words[1:])],
            capture_output=True, text=True, encoding="utf-8", check=False,
        )  # fmt: skip
        assert fixed.returncode == 0, (command, fixed.stderr)
        selected = [(Path(e["file"]).name, e["line"]) for e in json.loads(fixed.stdout)["entries"]]
        assert selected == [("odd.xml", line)], command


def test_the_suggested_command_refits_the_file_checked_not_the_default_database(tmp_path):
    path = _awkward_database(tmp_path)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (line, message), *_ = _check(path.parent, "json").items()
    words = shlex.split(_suggested(message))
    assert words[-2:] == ["--", str(path)]
    fixed = subprocess.run(
        [sys.executable, "-m", "lensaudit", *_with_json(words[1:])],
        capture_output=True, text=True, encoding="utf-8", check=False, cwd=elsewhere,
    )  # fmt: skip
    assert fixed.returncode == 0, fixed.stderr
    assert [(e["file"], e["line"]) for e in json.loads(fixed.stdout)["entries"]] == [
        (str(path), line)
    ]
