"""A line on stderr while the gaze kernels compile (the first use after an install), none otherwise.

numba tells when it compiles (not when it loads a kernel from its cache): from the first kernel of
this package it compiles until that compile ends, a line after one second says what is happening,
redrawn with the elapsed time on a terminal, and a last line says how long it took. With
``CPC2URDF_PROGRESS=0`` in the environment it is silent (as :mod:`cpc2urdf.progress`).
"""

from __future__ import annotations

import os
import sys
import threading
import time
from typing import Any

from numba.core import event

_PACKAGE = __name__.rsplit(".", 1)[0]
DELAY = 1.0  # [s]: a compile (or cache load) shorter than this says nothing
LABEL = "gaze: compiling the solver (first use; cached for later runs)"


class _CompileNotice(event.Listener):  # type: ignore[misc]
    """Counts nested compiles from the first of this package's kernels; draws the line meanwhile."""

    def __init__(self) -> None:
        self.depth = 0
        self.start = 0.0
        self.done = threading.Event()
        self.thread: threading.Thread | None = None
        self.shown = False

    def on_start(self, ev: Any) -> None:
        if self.depth == 0:
            dispatcher = ev.data.get("dispatcher")
            module = getattr(getattr(dispatcher, "py_func", None), "__module__", "") or ""
            if not module.startswith(_PACKAGE) or os.environ.get("CPC2URDF_PROGRESS", "1") == "0":
                return
            self.start = time.perf_counter()
            self.done.clear()
            self.shown = False
            self.thread = threading.Thread(
                target=self._draw, name="gaze-compile-notice", daemon=True
            )
            self.thread.start()
        self.depth += 1

    def on_end(self, ev: Any) -> None:
        if self.depth == 0:
            return
        self.depth -= 1
        if self.depth == 0:
            self.done.set()
            if self.thread is not None:
                self.thread.join()
            if self.shown:
                sys.stderr.write(
                    f"\r{LABEL}: done in {time.perf_counter() - self.start:.1f} s\033[K\n"
                )
                sys.stderr.flush()

    def _draw(self) -> None:
        if self.done.wait(DELAY):
            return
        self.shown = True
        live = sys.stderr.isatty()
        sys.stderr.write(f"{LABEL} ..." if live else f"{LABEL} ...\n")
        sys.stderr.flush()
        while live and not self.done.wait(1.0):
            sys.stderr.write(f"\r{LABEL} ... {time.perf_counter() - self.start:.0f} s")
            sys.stderr.flush()


_NOTICE = _CompileNotice()


def install() -> None:
    """Listen to numba's compile events (once)."""
    if not getattr(install, "done", False):
        event.register("numba:compile", _NOTICE)
        install.done = True  # type: ignore[attr-defined]
