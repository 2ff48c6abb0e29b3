"""Shared plumbing for the ``bench`` and ``study`` command groups.

Each benchmark or study is a module with ``main(argv: list[str]) -> int`` that parses its own
options; the group command only picks the module by name. Add one line to the dict to register.
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Mapping


def add_group(
    subparsers: argparse._SubParsersAction,  # type: ignore[type-arg]
    name: str,
    help_text: str,
    registry: Mapping[str, tuple[str, str]],
) -> None:
    """Register ``cpc2urdf NAME WHICH [options...]``, dispatching to ``registry[WHICH][0].main``."""
    lines = "\n".join(f"  {k:10s} {desc}" for k, (_, desc) in registry.items())
    p = subparsers.add_parser(
        name,
        help=help_text,
        description=f"{help_text}\n\navailable:\n{lines}\n\nRun 'cpc2urdf {name} WHICH --help' for its options.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "which", choices=sorted(registry), metavar="WHICH", help=", ".join(sorted(registry))
    )
    p.add_argument("options", nargs=argparse.REMAINDER, help="options of that " + name)

    def run(args: argparse.Namespace) -> int:
        module = importlib.import_module(registry[args.which][0])
        return int(module.main(list(args.options)))

    p.set_defaults(run=run)
