"""Capture what a library prints, down to the file descriptors: :func:`captured_output`.

Pinocchio parses URDFs with urdfdom in-process, and urdfdom reports problems by writing to the
process's stderr from C++; yourdfpy logs through Python's ``logging``. Neither text is ours to
show: the contract is one line naming the problem, so the callers turn what they need of it into
that line. Redirecting ``sys.stderr`` is not enough for the C++ part, so file descriptors 1 and 2
are pointed at a temporary file for the duration (not thread-safe: the CLI is single-threaded).
"""

from __future__ import annotations

import contextlib
import ctypes
import io
import os
import sys
import tempfile
from collections.abc import Iterator


class CapturedOutput:
    """What was printed inside :func:`captured_output`.

    Attributes:
        text: stdout and stderr, Python's and the C/C++ libraries', once the block has ended.
    """

    def __init__(self) -> None:
        self.text = ""

    def error_lines(self) -> list[str]:
        """The lines of :attr:`text` that report an error (urdfdom's ``Error:`` lines), stripped."""
        return [
            ln.strip() for ln in self.text.splitlines() if ln.strip().lower().startswith("error")
        ]


def _flush_c_stdio() -> None:
    try:
        ctypes.CDLL(None).fflush(None)  # C's (and C++'s synced) buffered stdout
    except (OSError, AttributeError, TypeError):  # no C library to ask (e.g. Windows)
        pass


@contextlib.contextmanager
def captured_output() -> Iterator[CapturedOutput]:
    """Capture stdout and stderr at the file-descriptor level (C/C++ output included) and at
    Python's level (``sys.stdout``, ``sys.stderr``, ``logging``'s last-resort handler).

    Yields:
        A :class:`CapturedOutput` whose ``text`` is filled when the block ends.
    """
    captured = CapturedOutput()
    py_out, py_err = io.StringIO(), io.StringIO()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    _flush_c_stdio()
    with tempfile.TemporaryFile() as tmp:
        saved: list[tuple[int, int]] = []
        try:
            for fd in (1, 2):
                with contextlib.suppress(OSError):  # a closed descriptor: nothing to capture there
                    saved.append((fd, os.dup(fd)))
                    os.dup2(tmp.fileno(), fd)
            with contextlib.redirect_stdout(py_out), contextlib.redirect_stderr(py_err):
                yield captured
        finally:
            _flush_c_stdio()
            for fd, copy in saved:
                os.dup2(copy, fd)
                os.close(copy)
            tmp.seek(0)
            native = tmp.read().decode("utf-8", errors="replace")
            captured.text = native + py_out.getvalue() + py_err.getvalue()


__all__ = ["CapturedOutput", "captured_output"]
