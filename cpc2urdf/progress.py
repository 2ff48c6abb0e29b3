"""A small progress bar for long studies (stderr; no dependency).

Usage::

    for item in progress(items, "fig11"):
        ...

On a terminal it redraws one line at most every 0.2 s; elsewhere (a log file) it prints only the
final line with the elapsed time. With ``CPC2URDF_PROGRESS=0`` in the environment it is silent
(tests set this).
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Iterable, Iterator, Sized
from typing import TypeVar

T = TypeVar("T")


def progress(items: Iterable[T], label: str, total: int | None = None) -> Iterator[T]:
    """Yield ``items`` while drawing ``label [#####.....] k/n  elapsed  eta`` on stderr."""
    if total is None and isinstance(items, Sized):
        total = len(items)
    quiet = os.environ.get("CPC2URDF_PROGRESS", "1") == "0"
    # Redraw only on a terminal; in a log file (CI, `> out.txt`) print just the final line.
    live = not quiet and sys.stderr.isatty()
    start = last = time.perf_counter()
    k = 0
    drawn = False
    try:
        for k, item in enumerate(items, 1):
            yield item
            if _draw(label, k, total, start, last, live):
                drawn, last = True, time.perf_counter()
    except GeneratorExit:
        # Closed early (an error in the loop body): clear a half-drawn bar so the error that
        # follows stands alone on its line.
        if drawn:
            sys.stderr.write("\r\033[K")
            sys.stderr.flush()
        raise
    if not quiet and k:
        sys.stderr.write(f"\r{label}: {k} done in {time.perf_counter() - start:.1f}s" + " " * 30 + "\n")
        sys.stderr.flush()


def _draw(label: str, k: int, total: int | None, start: float, last: float, live: bool) -> bool:
    """Redraw the bar after item ``k`` if it is time to; True if it drew."""
    now = time.perf_counter()
    if not (live and (now - last > 0.2 or k == total)):
        return False
    elapsed = now - start
    if total:
        width = 30
        fill = int(width * k / total)
        eta = elapsed / k * (total - k)
        line = f"\r{label} [{'#' * fill}{'.' * (width - fill)}] {k}/{total} {elapsed:6.1f}s eta {eta:6.1f}s"
    else:
        line = f"\r{label} {k} {elapsed:6.1f}s"
    sys.stderr.write(line)
    sys.stderr.flush()
    return True


__all__ = [
    "progress",
]
