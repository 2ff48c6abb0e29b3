"""Board definition files ``cpc2urdf/board@1``: a standard calibration board in OpenCV's terms.

JSON, one object (``docs/images.md``)::

    {"format": "cpc2urdf/board@1", "kind": "charuco", "squares": [7, 5], "square_size": 30,
     "marker_size": 22, "dictionary": "DICT_5X5_100", "units": "mm"}

    {"format": "cpc2urdf/board@1", "kind": "chessboard", "pattern_size": [9, 6], "square_size": 20,
     "units": "mm"}

    {"format": "cpc2urdf/board@1", "kind": "asymmetric_circles", "pattern_size": [4, 11],
     "spacing": 10, "circle_radius": 3.5, "units": "mm"}

Keys by kind (meanings in :mod:`~cpc2urdf.identification.vision.boards.board`):

- every kind: ``format``, ``kind``, ``units`` (``m``, ``cm``, ``mm``; default ``m``), ``margin``
  (white border around the pattern; default one square or spacing), ``name`` (optional);
- ``chessboard``: ``pattern_size`` (inner corners), ``square_size``;
- ``charuco``: ``squares``, ``square_size``, ``marker_size``, ``dictionary``,
  ``first_marker_id`` (default 0);
- ``circles``, ``asymmetric_circles``: ``pattern_size``, ``spacing``, ``circle_radius``.

Every problem raises :class:`cpc2urdf.errors.InputFileError` with one line naming the file and the
field (``board.json: marker_size must be smaller than square_size (30 mm), got 35``); unknown keys
are refused (a misspelt key would otherwise be silently ignored).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import cv2

from cpc2urdf.errors import InputFileError
from cpc2urdf.files.jsonio import read_json, require_format, write_json
from cpc2urdf.files.units import LENGTH_UNITS
from cpc2urdf.identification.vision.boards.board import BOARD_KINDS, Board

BOARD_FORMAT = "cpc2urdf/board@1"
_COMMON = ("format", "kind", "units", "margin", "name")
_KEYS: dict[str, tuple[str, ...]] = {
    "chessboard": ("pattern_size", "square_size"),
    "charuco": ("squares", "square_size", "marker_size", "dictionary", "first_marker_id"),
    "circles": ("pattern_size", "spacing", "circle_radius"),
    "asymmetric_circles": ("pattern_size", "spacing", "circle_radius"),
}
_OPTIONAL = ("units", "margin", "name", "first_marker_id")


def _int_pair(doc: Mapping[str, Any], key: str, least: int, path: Path) -> tuple[int, int]:
    v = doc[key]
    if (
        not isinstance(v, list)
        or len(v) != 2
        or not all(isinstance(x, int) and not isinstance(x, bool) for x in v)
        or min(v) < least
    ):
        raise InputFileError(
            path, f"{key} must be [cols, rows], two integers >= {least}, got {v!r}"
        )
    return int(v[0]), int(v[1])


def _length(
    doc: Mapping[str, Any], key: str, scale: float, path: Path, *, zero_ok: bool = False
) -> float:
    v = doc[key]
    if (
        isinstance(v, bool)
        or not isinstance(v, (int, float))
        or not (v > 0 or (zero_ok and v == 0))
        or v != v
        or v == float("inf")
    ):
        raise InputFileError(
            path, f"{key} must be a {'non-negative' if zero_ok else 'positive'} length, got {v!r}"
        )
    return float(v) * scale


def board_from_json(doc: Any, path: str | os.PathLike[str] = "board") -> Board:
    """A :class:`~cpc2urdf.identification.vision.boards.board.Board` from a parsed ``cpc2urdf/board@1``
    object (module docstring); ``InputFileError`` naming ``path`` and the field."""
    p = Path(path)
    doc = require_format(doc, BOARD_FORMAT, p)
    kind = doc.get("kind")
    if kind not in BOARD_KINDS:
        raise InputFileError(p, f"kind must be one of {', '.join(BOARD_KINDS)}, got {kind!r}")
    allowed = set(_COMMON) | set(_KEYS[kind])
    for k in doc:
        if k not in allowed:
            raise InputFileError(
                p, f"unknown key {k!r} for a {kind} board (expected {', '.join(sorted(allowed))})"
            )
    for k in _KEYS[kind]:
        if k not in doc and k not in _OPTIONAL:
            raise InputFileError(
                p, f"missing key {k!r} (a {kind} board needs {', '.join(_KEYS[kind])})"
            )
    unit = doc.get("units", "m")
    if unit not in LENGTH_UNITS:
        raise InputFileError(p, f"units must be one of {sorted(LENGTH_UNITS)}, got {unit!r}")
    s = LENGTH_UNITS[unit]
    name = doc.get("name", p.name)
    if not isinstance(name, str) or not name:
        raise InputFileError(p, f"name must be a non-empty string, got {name!r}")
    args: dict[str, Any] = {"kind": kind, "name": name}
    if kind == "chessboard":
        args["size"] = _int_pair(doc, "pattern_size", 2, p)
        args["square_size"] = _length(doc, "square_size", s, p)
        pitch = args["square_size"]
    elif kind == "charuco":
        args["size"] = _int_pair(doc, "squares", 3, p)
        args["square_size"] = _length(doc, "square_size", s, p)
        args["marker_size"] = _length(doc, "marker_size", s, p)
        if args["marker_size"] >= args["square_size"]:
            raise InputFileError(
                p,
                f"marker_size must be smaller than square_size ({doc['square_size']} {unit}), "
                f"got {doc['marker_size']}",
            )
        dic = doc["dictionary"]
        if not isinstance(dic, str) or not dic.startswith("DICT_") or not hasattr(cv2.aruco, dic):
            raise InputFileError(
                p,
                f"dictionary must be an OpenCV ArUco dictionary name such as DICT_5X5_100, got {dic!r}",
            )
        first = doc.get("first_marker_id", 0)
        if isinstance(first, bool) or not isinstance(first, int) or first < 0:
            raise InputFileError(p, f"first_marker_id must be an integer >= 0, got {first!r}")
        args.update(dictionary=dic, first_marker_id=first)
        n_dict = int(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dic)).bytesList.shape[0])
        n_markers = (args["size"][0] * args["size"][1]) // 2
        if first + n_markers > n_dict:
            raise InputFileError(
                p,
                f"the board needs marker ids {first}..{first + n_markers - 1} but {dic} has only "
                f"{n_dict} markers (choose a larger dictionary or a smaller first_marker_id)",
            )
        pitch = args["square_size"]
    else:
        args["size"] = _int_pair(doc, "pattern_size", 2 if kind == "circles" else 2, p)
        args["spacing"] = _length(doc, "spacing", s, p)
        args["circle_radius"] = _length(doc, "circle_radius", s, p)
        gap = args["spacing"] * (
            2**0.5 if kind == "asymmetric_circles" else 1.0
        )  # nearest neighbours
        if args["circle_radius"] >= 0.4 * gap:
            raise InputFileError(
                p,
                f"circle_radius must be below 0.4 x the distance between neighbouring circles "
                f"({0.4 * gap / s:g} {unit}), got {doc['circle_radius']}",
            )
        pitch = args["spacing"]
    args["margin"] = _length(doc, "margin", s, p, zero_ok=True) if "margin" in doc else pitch
    return Board(**args)


def load_board(path: str | os.PathLike[str]) -> Board:
    """Read a ``cpc2urdf/board@1`` file (module docstring).

    Raises:
        InputFileError: Missing or unreadable file, not JSON, wrong format tag, a missing,
            unknown or invalid field (one line naming the file and the field).
    """
    p = Path(path)
    return board_from_json(read_json(p), p)


def save_board(board: Board, path: str | os.PathLike[str]) -> Path:
    """Write ``board`` as a ``cpc2urdf/board@1`` file in millimetres, atomically."""
    mm = LENGTH_UNITS["mm"]
    doc: dict[str, Any] = {"format": BOARD_FORMAT, "name": board.name}
    for k, v in board.to_json().items():
        doc[k] = round(v / mm, 9) if isinstance(v, float) else v
    doc["units"] = "mm"
    return write_json(path, doc)


__all__ = ["BOARD_FORMAT", "board_from_json", "load_board", "save_board"]
