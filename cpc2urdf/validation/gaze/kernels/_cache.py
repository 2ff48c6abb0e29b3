"""numba's cache of the gaze kernels, invalidated by an edit of any of their modules.

numba keys a cached kernel on its own source file; a kernel's machine code holds the code of every
kernel it calls, which may be in another file of this package. So each kernel of the package is
keyed on the contents of all of them (one hash, read once per process), which also names its
cache files.
"""

from __future__ import annotations

import functools
import hashlib
import os
from typing import Any

from numba.core import caching

_DIR = os.path.dirname(os.path.abspath(__file__))


@functools.cache
def _package_stamp() -> bytes:
    """One hash of the contents of every module of this package."""
    digest = hashlib.sha256()
    for name in sorted(os.listdir(_DIR)):
        if name.endswith(".py"):
            with open(os.path.join(_DIR, name), "rb") as f:
                digest.update(name.encode() + b"\0" + f.read())
    return digest.digest()


def _keyed_on_the_package(base: Any) -> Any:
    """``base`` (a numba cache locator) for this package's kernels, keyed on :func:`_package_stamp`."""

    class Locator(base):  # type: ignore[misc, valid-type]
        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            if os.path.dirname(os.path.abspath(py_file)) != _DIR:
                return None
            return super().from_function(py_func, py_file)

        def get_source_stamp(self) -> Any:
            return _package_stamp()

        def get_disambiguator(self) -> str:
            # the package's version in the file name too: an index written by other sources is never
            # read (numba unpickles an index before it compares stamps, and one that names a
            # renamed module's classes fails there)
            return f"{super().get_disambiguator()}-{_package_stamp().hex()[:12]}"

    Locator.__name__ = f"GazeKernels{base.__name__}"
    return Locator


def install() -> None:
    """Put the package's locators first (once)."""
    classes = caching.CacheImpl._locator_classes
    if not any(c.__name__.startswith("GazeKernels") for c in classes):
        bases = (
            caching.UserProvidedCacheLocator,
            caching.InTreeCacheLocator,
            caching.UserWideCacheLocator,
        )
        classes[:0] = [_keyed_on_the_package(b) for b in bases]
