"""A small progress bar for long studies (stderr; no dependency).

Usage::

    for item in progress(items, "fig11"):
        ...

On a terminal it redraws one line at most every 0.2 s; elsewhere (a log file) it prints only the
final line with the elapsed time. With ``CPC2URDF_PROGRESS=0`` in the environment it is silent
(tests set this).
"""

from __future__ import annotations

import itertools
import os
import sys
import time
from collections.abc import Generator, Iterable, Iterator, Sequence, Sized
from contextlib import contextmanager
from typing import TypeVar

T = TypeVar("T")


def progress(items: Iterable[T], label: str, total: int | None = None) -> Generator[T, None, None]:
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
        sys.stderr.write(
            f"\r{label}: {k} done in {time.perf_counter() - start:.1f}s" + " " * 30 + "\n"
        )
        sys.stderr.flush()


@contextmanager
def progress_checked(items: Sequence[T], label: str, show: bool = True) -> Iterator[Iterator[T]]:
    """``with progress_checked(items, label) as it: for x in it: ...`` draws the bar like
    :func:`progress`, but prints its "done" line only when the block ends without an error; an
    error clears a half-drawn bar first, so that a refusal is the only line on stderr."""
    if not show:
        yield iter(items)
        return
    bar = progress(items, label)
    try:
        yield itertools.islice(bar, len(items))  # islice does not ask the bar past the last item
    except BaseException:
        bar.close()
        raise
    next(bar, None)


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
    "progress_checked",
]
