"""The ``lensaudit`` command: one click group, one module per subcommand."""

from __future__ import annotations

import click

from .. import __version__
from .scan import scan


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="lensaudit")
def main() -> None:
    """Audit lens-distortion models for fold-back.

    A polynomial distortion D(r) = r F(r) is only invertible up to its first
    local maximum, r_max; beyond it, points outside the field of view land
    inside the image. lensaudit computes r_max for every ptlens, poly3 and
    poly5 model of a Lensfun database and compares it with the image corner.

    Exit codes: 0 done, 2 bad usage or input that could not be read.
    """


main.add_command(scan)
