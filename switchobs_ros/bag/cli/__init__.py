"""``switchobs_bag``: rosbag2 bags through the switchobs estimator, live and offline.

::

    switchobs_bag generate OUT [--schedule periodic:2,0.6] [--rate 100] [--duration 30] [--noise 0]
                               [--seed 0] [--storage mcap|sqlite3]
    switchobs_bag record OUT [--topics T ...] [--duration S] [--count N] [--storage ...] [--ros-args ...]
    switchobs_bag play BAG [--rate 1] [--loop | --loops N] [--no-clock] [--wait-node estimator] [--ros-args ...]
    switchobs_bag estimate BAG -o OUT [--csv F] [--params-file F ...] [-p name:=value ...] [--gain-table F]
    switchobs_bag report BAG [-o report.png] [--summary summary.md]
    switchobs_bag info BAG

A bad bag (missing, truncated, a missing topic, a wrong type) or a bad option gives one line on
stderr, ``switchobs_bag: error: ...``, and exit code 2; a timeout waiting for subscribers or
publishers exits 3.
"""

from __future__ import annotations

import argparse
import sys

from switchobs_core.cli._common import OneLineParser
from switchobs_core.exceptions import SwitchobsError, one_line
from switchobs_core.threads import single_threaded_blas

from . import estimate, generate, info, play, record, report
from ._common import PROG, split_ros_args

__all__ = ["main", "build_parser", "SUBCOMMANDS"]

#: One module per subcommand, each with ``register(sub)`` and ``run(args, ros_argv)``.
SUBCOMMANDS = (generate, record, play, estimate, report, info)


def build_parser() -> argparse.ArgumentParser:
    ap = OneLineParser(prog=PROG, description="rosbag2 bags through the switchobs estimator.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    for mod in SUBCOMMANDS:
        mod.register(sub)
    return ap


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``switchobs_bag`` console script."""
    single_threaded_blas()
    argv = list(sys.argv[1:] if argv is None else argv)
    own, ros_argv = split_ros_args(argv)
    args = build_parser().parse_args(own)
    try:
        return int(args.func(args, ros_argv) or 0)
    except TimeoutError as err:
        print(f"{PROG}: error: {one_line(err)}", file=sys.stderr)
        return 3
    except (SwitchobsError, ValueError, OSError) as err:   # ValueError: a library refusing a value
        print(f"{PROG}: error: {one_line(err)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
