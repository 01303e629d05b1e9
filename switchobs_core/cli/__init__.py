"""The ``switchobs`` command: offline design, inspection, reproduction, simulation, certificates.

``switchobs design | show | reproduce | simulate | certify | plan`` (``switchobs CMD --help``).
Each subcommand lives in its own module exposing ``register(subparsers)``, which adds
the subparser and sets ``func(args) -> exit code``. Errors of the project's own type are
printed as one line and exit with code 2; nothing else is caught.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from .._version import __version__
from ..exceptions import SwitchobsError, one_line
from ..threads import single_threaded_blas
from ._common import OneLineParser

__all__ = ["main", "SUBCOMMANDS"]

SUBCOMMANDS = ("design", "show", "reproduce", "simulate", "certify", "plan")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="switchobs",
        description="Switched Luenberger observers for systems whose outputs are available one channel at a time.",
    )
    parser.add_argument("--version", action="version", version=f"switchobs {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name in SUBCOMMANDS:
        try:
            mod = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as err:
            if err.name == f"{__name__}.{name}":
                continue
            raise
        mod.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``switchobs`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    single_threaded_blas()  # small matrices: see switchobs_core.threads
    try:
        return int(args.func(args) or 0)
    except SwitchobsError as err:
        print(f"switchobs {args.command}: error: {one_line(err)}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # the reader went away (`switchobs show T | head`): not an error of ours; silence the
        # interpreter's flush of the closed stdout at exit (Python docs, "Note on SIGPIPE")
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except OSError as err:     # a file the command writes: a full disk, a read-only folder
        print(f"switchobs {args.command}: error: {one_line(err)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("switchobs: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
