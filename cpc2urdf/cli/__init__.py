"""The ``cpc2urdf`` command line: ``main(argv) -> int``.

Each sub-command lives in its own module of this package and exposes ``add_parser(subparsers)``,
which registers the command and sets ``run=<function(args) -> int>``. Heavy imports happen inside
``run`` so that ``cpc2urdf --help`` stays fast.

Exit codes: 0 success, 1 a check failed (e.g. ``check`` found a discrepancy), 2 bad input (one
line on stderr naming the problem, no traceback, no partial output file). No command writes over
a file it reads (:func:`cpc2urdf.argparsing.check_outputs_are_not_inputs`), except where it
updates one on purpose (``handeye --model M -o M``).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from collections.abc import Sequence

from cpc2urdf.argparsing import OneLineParser, check_outputs_are_not_inputs, exit_code
from cpc2urdf.errors import Cpc2UrdfError

# Sub-command modules, in the order `--help` lists them.
COMMANDS = (
    "demo",
    "export",
    "check",
    "bench",
    "study",
    "simulate",
    "plan",
    "measure",
    "bag",
    "calibrate",
    "identify",
    "accuracy",
    "handeye",
    "view",
    "gaze",
    "reach",
)


def build_parser() -> argparse.ArgumentParser:
    from cpc2urdf.version import __version__

    parser = OneLineParser(
        prog="cpc2urdf",
        description="Calibrate active robot heads (CPC identification, hand-eye) and export a URDF.",
    )
    parser.add_argument("--version", action="version", version=f"cpc2urdf {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=OneLineParser)
    sub.required = True
    for name in COMMANDS:
        importlib.import_module(f"cpc2urdf.cli.{name}").add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit code (0 ok, 1 check failed, 2 bad input)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # --help, --version, or a usage error
        return exit_code(e)
    try:
        check_outputs_are_not_inputs(args)
        return int(args.run(args))
    except SystemExit as e:  # a study's or benchmark's own parser (--help, a usage error)
        return exit_code(e)
    except Cpc2UrdfError as e:
        print(f"cpc2urdf {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"cpc2urdf {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (`cpc2urdf ... | head`): not an error of ours; silence the
        # interpreter's own flush of stdout at exit.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
