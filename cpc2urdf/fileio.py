"""Reading JSON files with one clear error, and writing files atomically.

An output file is written to a temporary file in the same folder and renamed over the target, so
a failure never leaves a partial or corrupted file behind.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from cpc2urdf.errors import InputFileError, OutputError


def read_text_file(path: str | os.PathLike[str], expected: str, encoding: str = "utf-8") -> str:
    """The text of a user's input file, or one :class:`InputFileError` naming the file and why:
    missing, a folder, binary (undecodable or with NUL bytes), unreadable.

    Args:
        path: The file.
        expected: What it should be, for the message (e.g. ``"a JSON file"``).
        encoding: Text encoding (``"utf-8-sig"`` accepts a byte-order mark).
    """
    p = Path(path)
    if not p.exists():
        raise InputFileError(p, "no such file")
    if p.is_dir():
        raise InputFileError(p, f"is a folder, expected {expected}")
    try:
        text = p.read_text(encoding=encoding)
    except UnicodeDecodeError:
        raise InputFileError(p, f"is a binary file, expected {expected}") from None
    except OSError as e:
        raise InputFileError(p, f"cannot read ({e.strerror})") from None
    if "\x00" in text:
        raise InputFileError(p, f"is a binary file, expected {expected}")
    return text


def read_json(path: str | os.PathLike[str]) -> Any:
    """Load a JSON file, raising :class:`InputFileError` naming the file and the problem."""
    p = Path(path)
    text = read_text_file(p, "a JSON file")
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as e:
        raise InputFileError(p, f"not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})") from e
    except ValueError as e:
        raise InputFileError(p, str(e)) from e


def _reject_constant(name: str) -> float:
    # json accepts NaN/Infinity by default; a calibration file must not contain them.
    raise ValueError(f"non-finite number {name} is not allowed")


def require_format(doc: Any, expected: str, path: object) -> Mapping[str, Any]:
    """Check that ``doc`` is an object whose ``format`` tag is ``expected`` (any ``@`` version
    of the same family is named in the error)."""
    if not isinstance(doc, Mapping):
        raise InputFileError(path, f"expected a JSON object with \"format\": \"{expected}\"")
    tag = doc.get("format")
    if tag != expected:
        raise InputFileError(path, f"format is {tag!r}, expected {expected!r}")
    return doc


def make_folder(path: str | os.PathLike[str]) -> Path:
    """Create the output folder ``path`` (and its parents) if missing, or :class:`OutputError`."""
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputError(f"{p}: cannot create folder ({e.strerror})") from e
    return p


def write_atomic(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` to ``path`` atomically (temp file in the same folder, then rename).

    Raises:
        OutputError: The folder does not exist or is not writable, or the path is a folder.
    """
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    if p.is_dir():
        raise OutputError(f"{p}: is a folder, expected a file path")
    if not folder.is_dir():
        raise OutputError(f"{p}: cannot write, folder {folder} does not exist")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=folder)
    except OSError as e:
        raise OutputError(f"{p}: cannot write ({e.strerror})") from e
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        # mkstemp creates 0600; give the file the mode a plain open() would have given it.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, p)
    except OSError as e:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise OutputError(f"{p}: cannot write ({e.strerror})") from e
    return p


def dumps(doc: Any) -> str:
    """Deterministic JSON text (sorted keys are not used: field order is part of the format)."""
    return json.dumps(doc, indent=2, allow_nan=False) + "\n"


def write_json(path: str | os.PathLike[str], doc: Any) -> Path:
    """Atomically write ``doc`` as JSON (NaN/inf refused)."""
    try:
        text = dumps(doc)
    except ValueError as e:
        raise OutputError(f"{path}: refusing to write non-finite numbers ({e})") from e
    return write_atomic(path, text)


def finite_float(value: Any, where: str) -> float:
    """``value`` as a finite float, or ``ValueError`` naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{where} must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"{where} must be finite, got {value!r}")
    return v


def float_list(value: Any, n: int, where: str) -> list[float]:
    """``value`` as a list of ``n`` finite floats, or ``ValueError`` naming ``where``."""
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise ValueError(f"{where} must be a list of {n} numbers, got {value!r}")
    return [finite_float(v, f"{where}[{i}]") for i, v in enumerate(value)]


__all__ = [
    "dumps",
    "finite_float",
    "float_list",
    "make_folder",
    "read_json",
    "read_text_file",
    "require_format",
    "write_atomic",
    "write_json",
]
