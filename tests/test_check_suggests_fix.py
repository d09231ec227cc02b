"""Each fold that check reports names the `lensaudit fix` command that refits it,
and that command, run as written, selects exactly that entry."""

from __future__ import annotations

import json
import re
import shlex
import shutil
import subprocess

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
        command = re.search(r"`(lensaudit fix [^`]+)` refits it", finding["message"]).group(1)
        arguments = shlex.split(command)[1:] + [str(bundled_db), "--format", "json"]
        fixed = CliRunner().invoke(main, arguments)
        assert fixed.exit_code == 0, fixed.output
        selected = [(e["file"], e["line"]) for e in json.loads(fixed.output)["entries"]]
        assert selected == [(finding["file"].split("/")[-1], finding["line"])], command


@pytest.mark.parametrize("name", ['Odd "$HOME" `x` \\ lens', "Plain 14-42mm f/3.5-5.6", "It's"])
def test_the_suggested_lens_name_survives_a_posix_shell(name):
    entry = DistortionEntry("x.xml", 1, "Maker", name, (), "rectilinear", 1.0, 1.5, "ptlens", 11.0)
    command = re.search(
        r"`lensaudit fix --lens (.+) --focal 11` refits it", check._fix_suggestion(entry)
    )
    if shutil.which("bash") is None:
        pytest.skip("no bash to judge the quoting")
    echoed = subprocess.run(
        ["bash", "-c", f"printf %s {command.group(1)}"], capture_output=True, text=True, check=True
    ).stdout
    assert echoed == name
