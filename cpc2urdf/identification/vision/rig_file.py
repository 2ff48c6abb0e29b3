"""Stereo rig calibration files: the OpenCV ``FileStorage`` YAML that ``cv2.stereoCalibrate`` users have.

A rig file holds the two cameras' intrinsics and the pose of the left camera in the right one,
exactly as ``cv2.stereoCalibrate`` returns them (``x_right = R x_left + T``)::

    %YAML:1.0
    ---
    K1: !!opencv-matrix {rows: 3, cols: 3, dt: d, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}
    D1: !!opencv-matrix {rows: 1, cols: 5, dt: d, data: [k1, k2, p1, p2, k3]}
    K2: ...
    D2: ...
    R:  !!opencv-matrix {rows: 3, cols: 3, ...}
    T:  !!opencv-matrix {rows: 3, cols: 1, ...}
    image_size: [1280, 1024]      # optional: [width, height]
    units: mm                     # optional: unit of T (m, cm or mm); default m

Accepted aliases: ``M1``/``M2`` or ``cameraMatrix1``/``cameraMatrix2`` for ``K1``/``K2``
(OpenCV's ``stereo_calib.cpp`` sample writes ``M1``), ``distCoeffs1``/``distCoeffs2`` for
``D1``/``D2``, ``imageSize`` or ``image_width`` + ``image_height`` for ``image_size``. ``D`` may
have 4 or 5 coefficients (more only if the extra rational/prism terms are zero: the rig model is
OpenCV's 5-term one). ``T`` has no unit in OpenCV's file, so a file without ``units`` whose
baseline is longer than 5 m is refused rather than read as metres (it is almost surely in mm).

The result is a :class:`cpc2urdf.identification.vision.stereo.StereoRig` (world = left camera). Any
problem raises :class:`cpc2urdf.errors.InputFileError` naming the file and the key.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import InputFileError, OutputError
from cpc2urdf.files.jsonio import read_text_file, write_atomic
from cpc2urdf.files.units import LENGTH_UNITS
from cpc2urdf.identification.vision.stereo import StereoRig

Array = NDArray[np.float64]

ALIASES: dict[str, tuple[str, ...]] = {
    "K1": ("K1", "M1", "cameraMatrix1"),
    "D1": ("D1", "distCoeffs1"),
    "K2": ("K2", "M2", "cameraMatrix2"),
    "D2": ("D2", "distCoeffs2"),
    "R": ("R",),
    "T": ("T",),
}
MAX_BASELINE_WITHOUT_UNITS = 5.0  # [m]: a longer T without a 'units' key is refused as ambiguous
RIG_ROTATION_TOL = 1e-5  # [-]: max |R^T R - I| entry accepted for R in a rig file


# A rig file holds a few matrices (K1, D1, ..., each a mapping of rows/cols/dt/data): a few levels
# of nesting. OpenCV's parsers recurse without a limit and crash the process (segfault) on deeply
# nested input, so depth is checked on the text first.
RIG_MAX_DEPTH = 16


def _nesting_depth(text: str) -> int:
    """Deepest nesting of a FileStorage text: brackets (JSON/YAML flow) or YAML block sequences
    and indentation, whichever is deeper. Quoted strings are skipped."""
    depth = deepest = 0
    quote = ""
    for ch in text:
        if quote:
            quote = "" if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth = max(depth - 1, 0)
    for line in text.splitlines():
        stripped = line.lstrip(" ")
        indent = len(line) - len(stripped)
        dashes = 0
        while stripped.startswith("- ") or stripped == "-":
            dashes += 1
            stripped = stripped[2:].lstrip(" ")
        deepest = max(deepest, dashes + indent // 2)
    return deepest


def _open(path: Path) -> cv2.FileStorage:
    text = read_text_file(path, "an OpenCV FileStorage YAML rig file")
    if _nesting_depth(text) > RIG_MAX_DEPTH:
        raise InputFileError(
            path,
            f"nested more than {RIG_MAX_DEPTH} levels deep; a rig file holds matrices "
            "(K1, D1, K2, D2, R, T as written by cv2.stereoCalibrate)",
        )
    _refuse_duplicate_keys(text, path)
    # OpenCV's YAML parser insists on the "%YAML:1.0" header; hand-written files often lack it.
    if path.suffix.lower() in (".yaml", ".yml") and not text.lstrip().startswith("%YAML"):
        text = "%YAML:1.0\n---\n" + text
    try:
        fs = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError) as e:
        cause = e.__cause__ or e.__context__ or e
        msg = str(cause).strip().splitlines()[-1] if str(cause).strip() else "parse error"
        raise InputFileError(path, f"not a readable OpenCV FileStorage file ({msg})") from None
    if not fs.isOpened():
        raise InputFileError(path, "cannot open as an OpenCV FileStorage file (YAML/XML/JSON)")
    return fs


_TOP_LEVEL_KEY = re.compile(r"([A-Za-z_][A-Za-z0-9_.-]*)\s*:")


def _refuse_duplicate_keys(text: str, path: Path) -> None:
    """A YAML key written twice at the top level (OpenCV keeps one of them silently)."""
    seen: dict[str, int] = {}
    for number, line in enumerate(text.splitlines(), start=1):
        m = _TOP_LEVEL_KEY.match(line)
        if m is None:
            continue
        key = m.group(1)
        if key in seen:
            raise InputFileError(path, f"duplicate key {key!r} (lines {seen[key]} and {number})")
        seen[key] = number


def _node(
    fs: cv2.FileStorage, key: str, path: Path, *, required: bool = True
) -> tuple[str, cv2.FileNode | None]:
    for name in ALIASES.get(key, (key,)):
        n = fs.getNode(name)
        if not n.empty() and not n.isNone():
            return name, n
    if required:
        names = " or ".join(ALIASES.get(key, (key,)))
        raise InputFileError(
            path,
            f"missing key {names} (expected K1, D1, K2, D2, R, T as written by cv2.stereoCalibrate)",
        )
    return key, None


def _matrix(node: cv2.FileNode, name: str, path: Path) -> Array:
    if node.isSeq():
        vals = [node.at(i) for i in range(node.size())]
        if not all(v.isReal() or v.isInt() for v in vals):
            raise InputFileError(path, f"{name} must be a matrix or a list of numbers")
        m = np.array([v.real() for v in vals], dtype=float)
    else:
        try:
            mat = node.mat()
        except cv2.error:
            mat = None
        if mat is None:
            raise InputFileError(
                path, f"{name} is not a matrix (expected !!opencv-matrix or a list of numbers)"
            )
        m = np.asarray(mat, dtype=float)
    if not np.all(np.isfinite(m)):
        raise InputFileError(path, f"{name} contains NaN or infinite values")
    return m


def _shaped(m: Array, name: str, shape: tuple[int, ...], path: Path) -> Array:
    if m.size != int(np.prod(shape)):
        raise InputFileError(
            path, f"{name} must have {' x '.join(map(str, shape))} values, got shape {m.shape}"
        )
    return m.reshape(shape)


def _distortion(m: Array, name: str, path: Path) -> Array:
    d = m.ravel()
    if d.size not in (4, 5, 8, 12, 14):
        raise InputFileError(path, f"{name} must have 4, 5, 8, 12 or 14 coefficients, got {d.size}")
    if d.size > 5:
        if np.any(d[5:] != 0):
            raise InputFileError(
                path,
                f"{name} has {d.size} coefficients with non-zero terms beyond k3 (rational/prism "
                "model); only OpenCV's 5-term model (k1, k2, p1, p2, k3) is supported",
            )
        d = d[:5]
    return np.concatenate([d, np.zeros(5 - d.size)])


def _image_size(fs: cv2.FileStorage, path: Path) -> tuple[int, int] | None:
    for name in ("image_size", "imageSize"):
        n = fs.getNode(name)
        if not n.empty() and not n.isNone():
            v = _matrix(n, name, path).ravel()
            if v.size != 2 or np.any(v <= 0) or np.any(v != np.round(v)):
                raise InputFileError(
                    path, f"{name} must be [width, height] in pixels, got {v.tolist()}"
                )
            return int(v[0]), int(v[1])
    w, h = fs.getNode("image_width"), fs.getNode("image_height")
    if not w.empty() and not h.empty():
        if not (w.isInt() and h.isInt()) or w.real() <= 0 or h.real() <= 0:
            raise InputFileError(path, "image_width and image_height must be positive integers")
        return int(w.real()), int(h.real())
    return None


def load_rig(
    path: str | os.PathLike[str], *, image_size: tuple[int, int] | None = None
) -> StereoRig:
    """Read a stereo rig from an OpenCV FileStorage file (see the module docstring).

    Args:
        path: The YAML (or XML/JSON) file.
        image_size: ``(width, height)`` [px] to use when the file has none; when both are given
            they must agree.

    Returns:
        The rig, ``T`` converted to metres.

    Raises:
        InputFileError: Missing file, corrupt file, a missing key, a wrong shape, a non-finite
            value, an invalid camera matrix, a non-rotation ``R``, an ambiguous unit.
    """
    p = Path(path)
    fs = _open(p)
    try:
        arrays: dict[str, Array] = {}
        for key in ("K1", "D1", "K2", "D2", "R", "T"):
            name, node = _node(fs, key, p)
            assert node is not None
            m = _matrix(node, name, p)
            if key.startswith("K"):
                K = _shaped(m, name, (3, 3), p)
                if K[0, 0] <= 0 or K[1, 1] <= 0 or np.any(K[2] != [0.0, 0.0, 1.0]) or K[1, 0] != 0:
                    raise InputFileError(
                        p,
                        f"{name} is not a camera matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0",
                    )
                arrays[key] = K
            elif key.startswith("D"):
                arrays[key] = _distortion(m, name, p)
            elif key == "R":
                if m.size == 3:  # a Rodrigues vector
                    m = np.asarray(cv2.Rodrigues(m.reshape(3, 1))[0], dtype=float)
                R = _shaped(m, name, (3, 3), p)
                defect = float(np.max(np.abs(R.T @ R - np.eye(3))))
                if defect > RIG_ROTATION_TOL or np.linalg.det(R) <= 0:
                    raise InputFileError(
                        p,
                        f"R is not a rotation matrix (max |R^T R - I| = {defect:.3g}, det = {np.linalg.det(R):.6g})",
                    )
                U, _, Vt = np.linalg.svd(R)
                arrays[key] = U @ Vt
            else:
                arrays[key] = _shaped(m, name, (3,), p)
        unit_node = fs.getNode("units")
        if unit_node.empty() or unit_node.isNone():
            unit = None
        else:
            unit = unit_node.string() if unit_node.isString() else ""
            if unit not in LENGTH_UNITS:
                raise InputFileError(
                    p, f"units must be one of {sorted(LENGTH_UNITS)} (the unit of T), got {unit!r}"
                )
        size = _image_size(fs, p)
    finally:
        fs.release()
    T = arrays["T"]
    if unit is None:
        if np.linalg.norm(T) > MAX_BASELINE_WITHOUT_UNITS:
            raise InputFileError(
                p,
                f"baseline |T| = {np.linalg.norm(T):.6g} is implausible in metres; add 'units: mm' "
                "(or cm, m) to the rig file to say which unit T is in",
            )
        unit = "m"
    T = T * LENGTH_UNITS[unit]
    if np.linalg.norm(T) == 0:
        raise InputFileError(p, "T is zero: the two cameras of a stereo rig must not coincide")
    if size is None:
        size = image_size
    elif image_size is not None and tuple(image_size) != size:
        raise InputFileError(
            p, f"image_size {list(size)} differs from the images' size {list(image_size)}"
        )
    if size is None:
        raise InputFileError(p, "missing key image_size ([width, height] in pixels)")
    return StereoRig(arrays["K1"], arrays["D1"], arrays["K2"], arrays["D2"], arrays["R"], T, size)


def save_rig(
    rig: StereoRig,
    path: str | os.PathLike[str],
    *,
    units: str = "m",
    extra: Sequence[tuple[str, Any]] = (),
) -> Path:
    """Write ``rig`` as an OpenCV FileStorage YAML file, atomically.

    Args:
        rig: The rig.
        path: Output file (``.yaml``/``.yml``).
        units: Unit of ``T`` in the file (``m``, ``cm`` or ``mm``), also written as ``units``.
        extra: More (name, matrix or string) entries after those, e.g. ``rms`` (readers ignore them).

    Raises:
        OutputError: The folder does not exist or cannot be written.
    """
    if units not in LENGTH_UNITS:
        raise ValueError(f"units must be one of {sorted(LENGTH_UNITS)}, got {units!r}")
    return _write_filestorage(
        path,
        [
            ("K1", np.asarray(rig.K1, dtype=np.float64)),
            ("D1", np.asarray(rig.D1, dtype=np.float64).reshape(1, -1)),
            ("K2", np.asarray(rig.K2, dtype=np.float64)),
            ("D2", np.asarray(rig.D2, dtype=np.float64).reshape(1, -1)),
            ("R", np.asarray(rig.R, dtype=np.float64)),
            ("T", (np.asarray(rig.T, dtype=np.float64) / LENGTH_UNITS[units]).reshape(3, 1)),
            ("image_size", np.array([[rig.image_size[0], rig.image_size[1]]], dtype=np.int32)),
            ("units", units),
            *extra,
        ],
    )


def _write_filestorage(path: str | os.PathLike[str], entries: list[tuple[str, Any]]) -> Path:
    """Write ``entries`` (name, matrix or string) as OpenCV FileStorage YAML, atomically: the
    text is made in memory and written by :func:`cpc2urdf.files.jsonio.write_atomic`."""
    try:
        fs = cv2.FileStorage(".yaml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
        for name, value in entries:
            fs.write(name, value)
        text = fs.releaseAndGetString()
    except cv2.error as e:
        raise OutputError(f"{path}: cannot write ({e})") from e
    return write_atomic(path, text)


# ---- single cameras (stage 2: the head's cameras) ----------------------------------------------------

CAMERA_ALIASES: dict[str, tuple[str, ...]] = {
    "K": ("K", "camera_matrix", "cameraMatrix", "M"),
    "D": ("D", "distortion_coefficients", "distCoeffs", "dist_coeffs"),
}


def load_camera(path: str | os.PathLike[str]) -> tuple[Array, Array, tuple[int, int]]:
    """Read one camera's intrinsics from an OpenCV FileStorage file (``cv2.calibrateCamera``).

    Keys: ``K`` (or ``camera_matrix``, as OpenCV's calibration sample writes, or
    ``cameraMatrix``), ``D`` (or ``distortion_coefficients``, ``distCoeffs``) and the image size
    (``image_size`` or ``image_width`` + ``image_height``).

    Returns:
        ``(K, D, (width, height))``: K (3, 3) [px], D (5,).

    Raises:
        InputFileError: As :func:`load_rig`, naming the file and the key.
    """
    p = Path(path)
    fs = _open(p)
    try:
        found = {}
        for key, names in CAMERA_ALIASES.items():
            node = None
            for name in names:
                n = fs.getNode(name)
                if not n.empty() and not n.isNone():
                    node = (name, n)
                    break
            if node is None:
                raise InputFileError(p, f"missing key {' or '.join(names)}")
            found[key] = (node[0], _matrix(node[1], node[0], p))
        kname, K = found["K"]
        K = _shaped(K, kname, (3, 3), p)
        if K[0, 0] <= 0 or K[1, 1] <= 0 or np.any(K[2] != [0.0, 0.0, 1.0]) or K[1, 0] != 0:
            raise InputFileError(
                p,
                f"{kname} is not a camera matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0",
            )
        D = _distortion(found["D"][1], found["D"][0], p)
        size = _image_size(fs, p)
    finally:
        fs.release()
    if size is None:
        raise InputFileError(
            p, "missing key image_size ([width, height] in pixels) or image_width + image_height"
        )
    return K, D, size


def save_camera(
    K: Array,
    D: Array,
    image_size: tuple[int, int],
    path: str | os.PathLike[str],
    *,
    extra: Sequence[tuple[str, Any]] = (),
) -> Path:
    """Write one camera's intrinsics (``K``, ``D``, ``image_size``) as FileStorage YAML, atomically;
    ``extra`` (name, matrix or string) entries follow (e.g. the calibration's ``rms``)."""
    return _write_filestorage(
        path,
        [
            ("K", np.asarray(K, dtype=np.float64)),
            ("D", np.asarray(D, dtype=np.float64).reshape(1, -1)),
            ("image_size", np.array([[image_size[0], image_size[1]]], dtype=np.int32)),
            *extra,
        ],
    )


__all__ = ["ALIASES", "CAMERA_ALIASES", "load_camera", "load_rig", "save_camera", "save_rig"]
