"""The ``lensaudit`` command: one click group, one module per subcommand.

Subcommand modules are imported only when their command runs, so that
``lensaudit scan`` does not pay for matplotlib, pandas or git plumbing.
"""

from __future__ import annotations

from importlib import import_module
from importlib.util import find_spec

import click

from ..commands import os_error_message, single_blas_thread
from ..formats import printable
from ..version import __version__

#: Subcommand name -> (module under lensaudit.cli, one-line help).
SUBCOMMANDS = {
    "scan": ("scan", "Compute r_max for every distortion entry (or audit vignetting, TCA)."),
    "report": ("report", "Write tables, figures and a self-contained HTML report."),
    "plot": ("plot", "Plot one entry's D(r), its undistortion, or r_max maps."),
    "check": ("check", "Fail when a database (or a change to it) has models that fold."),
    "project": ("project", "Project 3D points with a model, dropping those beyond r_max."),
    "history": ("history", "Audit every revision of a Lensfun database kept in git."),
    "fix": ("fix", "Refit models that fold inside their image; patch the XML with --write."),
}


# click 8.2 and newer show the help text through this error when no command is given.
_NO_ARGS_IS_HELP = getattr(click.exceptions, "NoArgsIsHelpError", ())


def _usage_error(ctx: click.Context, error: click.UsageError) -> None:
    """Bad usage as one line, as every other bad input, with where to read more; exit 2."""
    path = error.ctx.command_path if error.ctx is not None else ctx.command_path
    message = printable(f"{error.format_message()} (see '{path} --help')")
    click.echo(f"lensaudit: error: {message}", err=True)
    ctx.exit(2)


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return [
            name
            for name, (module, _) in SUBCOMMANDS.items()
            if find_spec(f"{__name__}.{module}") is not None
        ]

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in SUBCOMMANDS:
            return None
        name = f"{__name__}.{SUBCOMMANDS[cmd_name][0]}"
        try:
            module = import_module(name)
        except ModuleNotFoundError as error:  # that command is not installed
            if error.name != name:
                raise
            return None
        return getattr(module, cmd_name)

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        try:
            return super().parse_args(ctx, args)
        except click.UsageError as error:
            if isinstance(error, _NO_ARGS_IS_HELP):  # the help text, as asked
                raise
            _usage_error(ctx, error)
            raise  # not reached: _usage_error exits

    def invoke(self, ctx: click.Context):
        # No command does linear algebra: one BLAS thread, so that numpy starts
        # quicker and the process stays free to fork workers that parse files.
        single_blas_thread()
        # The last line of defence: a file-system problem that a command did
        # not foresee (a path too long, a permission) is one line, not a traceback.
        try:
            return super().invoke(ctx)
        except click.UsageError as error:
            _usage_error(ctx, error)
        except OSError as error:
            if isinstance(error, BrokenPipeError):
                raise

            click.echo(os_error_message(error), err=True)
            ctx.exit(2)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        # Listing help must not import every subcommand: use the short texts here.
        rows = [(name, SUBCOMMANDS[name][1]) for name in self.list_commands(ctx)]
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="lensaudit")
def main() -> None:
    """Audit lens-distortion models for fold-back.

    A polynomial distortion D(r) = r F(r) is only invertible up to its first
    local maximum, r_max; beyond it, points outside the field of view land
    inside the image. lensaudit computes r_max for every ptlens, poly3 and
    poly5 model of a Lensfun database and compares it with the image corner.

    Exit codes: 0 done, 1 findings (check), 2 bad usage or unreadable input.
    """
