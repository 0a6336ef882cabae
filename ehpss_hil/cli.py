"""``ehpss-hil``: one entry point; each subcommand lives in ``ehpss_hil/commands/<module>.py``,
named in :data:`ehpss_hil.commands.COMMANDS`.

Only the module of the command given is imported (``ehpss-hil --help`` imports none of them, nor
numpy). OpenBLAS is held to one thread before anything loads numpy: its idle worker threads spin
between the loops' tiny matvecs, and under a small address-space limit (``ulimit -v``) its
thread pool's start-up spun forever. Project errors become a one-line message and their exit
code (config 2, missing bus 3).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from . import __version__
from .blas import limit_blas_env
from .commands import COMMANDS
from .errors import run_console


def command_of(argv: Sequence[str]) -> str | None:
    """The subcommand named in ``argv`` (its first word that is not an option), if known."""
    for a in argv:
        if not a.startswith("-"):
            return a if a in COMMANDS else None
    return None


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The argument parser: every subcommand by name and help; ``command``'s own arguments
    (its module imported) when given."""
    parser = argparse.ArgumentParser(
        prog="ehpss-hil",
        description="Fault-tolerant (MMAC) controller for an electro-hydraulic position servo on CAN.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_) in COMMANDS.items():
        p = sub.add_parser(name, help=help_, description=help_)
        if name == command:
            mod = importlib.import_module(f"{__package__}.commands.{module}")
            mod.add_arguments(p)
            p.set_defaults(_run=mod.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``ehpss-hil`` console script."""
    limit_blas_env()
    args_in = list(sys.argv[1:] if argv is None else argv)
    command = command_of(args_in)
    # importing the command's module (numpy, …) may already run out of memory: one line too
    return run_console(f"ehpss-hil {command}" if command else "ehpss-hil", lambda: _run(args_in, command))


def _run(args_in: list[str], command: str | None) -> int:
    """Parse ``args_in`` (``command``'s module imported) and run the command."""
    parser = build_parser(command)
    args = parser.parse_args(args_in)
    if not hasattr(args, "_run"):
        parser.print_help()
        return 2
    return int(args._run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
