"""The one argument parser every command, study and benchmark uses.

argparse's own parser prints the whole usage block and raises ``SystemExit`` on a bad option; the
CLI contract is one line and exit code 2, returned by ``main`` rather than raised.
"""

from __future__ import annotations

import argparse
from typing import NoReturn


class OneLineParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose usage errors are one line on stderr and exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


def exit_code(e: SystemExit) -> int:
    """The exit code a ``SystemExit`` carries (``--help`` gives 0; a message or None is 2/0)."""
    if isinstance(e.code, int):
        return e.code
    return 0 if e.code is None else 2


__all__ = ["OneLineParser", "exit_code"]
