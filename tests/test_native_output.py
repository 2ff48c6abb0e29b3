"""``cpc2urdf.urdf.native_output.captured_output``: what C, C++ and Python libraries print inside the
block is captured at the file-descriptor level and never reaches the terminal."""

from __future__ import annotations

import ctypes
import logging
import os
import sys

import pytest

from cpc2urdf.urdf.native_output import captured_output


def test_fd_level_c_and_python_output_is_captured(capfd: pytest.CaptureFixture[str]) -> None:
    log = logging.getLogger("a.library.without.handlers")  # like yourdfpy's: logging's last resort
    log.propagate = False
    print("before")
    with captured_output() as out:
        os.write(2, b"Error:   from C++ on fd 2\n         at line 105 in pose.cpp\n")
        os.write(1, b"raw fd 1\n")
        ctypes.CDLL(None).printf(b"buffered C stdout\n")  # sits in C's buffer until flushed
        print("python stdout")
        print("python stderr", file=sys.stderr)
        log.error("Using different parsing approach.")
    print("after")
    cap = capfd.readouterr()
    assert cap.out == "before\nafter\n" and cap.err == ""
    for text in (
        "Error:   from C++ on fd 2",
        "raw fd 1",
        "buffered C stdout",
        "python stdout",
        "python stderr",
        "Using different parsing approach.",
    ):
        assert text in out.text
    assert out.error_lines() == ["Error:   from C++ on fd 2"]


def test_the_descriptors_are_restored_after_an_exception(capfd: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(RuntimeError), captured_output() as out:
        os.write(2, b"Error: lost\n")
        raise RuntimeError("boom")
    os.write(2, b"visible\n")
    assert capfd.readouterr().err == "visible\n" and "Error: lost" in out.text
