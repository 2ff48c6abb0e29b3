"""Folders of measurement images: one image per record and camera, and records that fail.

A measurement folder holds one sub-folder per camera with one image per record, named after the
record of ``joints.csv`` (:mod:`~cpc2urdf.identification.vision.joints_csv`); see
``docs/images.md`` for the stage-1 and stage-2 layouts. Images may be in any format of
:data:`IMAGE_EXTENSIONS`, 8- or 16-bit, grey or colour (read as 8-bit grey).

A record (or one plate in it) that cannot be measured is reported with the image, the plate and
the reason; the ``on_error`` policies (:data:`ON_ERROR`) are ``"stop"`` (raise at the first
one), ``"skip"`` (leave that plate out of that record) and ``"skip-record"`` (drop the whole
record); both skips list every problem (:func:`report_problem`).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import ConfigurationError, Cpc2UrdfError, InputFileError, OutputError
from cpc2urdf.identification.vision.detect import DetectionError

IMAGE_EXTENSIONS = (".png", ".tif", ".tiff", ".bmp", ".pgm", ".jpg", ".jpeg")
ON_ERROR = ("skip", "skip-record", "stop")


# ---- reading and writing images -------------------------------------------------------------------


def find_image(folder: Path, record: str) -> Path | None:
    """The image file ``folder/<record>.<ext>`` (first of :data:`IMAGE_EXTENSIONS`), or None.
    A record that already names a file with its extension is taken as is."""
    if Path(record).suffix.lower() in IMAGE_EXTENSIONS and (folder / record).is_file():
        return folder / record
    for ext in IMAGE_EXTENSIONS:
        for e in (ext, ext.upper()):
            p = folder / f"{record}{e}"
            if p.is_file():
                return p
    return None


def read_grey(path: Path) -> NDArray[np.uint8]:
    """An image as 8-bit grey (colour converted, 16-bit scaled).

    Raises:
        InputFileError: Missing, unreadable or not an image.
    """
    data = np.fromfile(str(path), dtype=np.uint8) if path.is_file() else None
    if data is None:
        raise InputFileError(path, "no such image file")
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)  # our message says it once
    try:
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    finally:
        cv2.utils.logging.setLogLevel(level)
    if img is None:
        raise InputFileError(path, "not a readable image (corrupt or unsupported format)")
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    if img.dtype == np.uint16:
        img = (img / 257.0).round().astype(np.uint8)
    elif img.dtype != np.uint8:
        raise InputFileError(path, f"unsupported pixel type {img.dtype} (expected 8 or 16 bit)")
    return np.asarray(img, dtype=np.uint8)


def write_image(path: str | os.PathLike[str], image: NDArray[np.uint8]) -> None:
    """Write an image losslessly (PNG) and atomically, raising ``OutputError`` on failure."""
    p = Path(str(path))
    if not p.parent.is_dir():
        raise OutputError(f"{p}: cannot write, folder {p.parent} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{p.stem}.", suffix=p.suffix or ".png", dir=p.parent)
    os.close(fd)
    try:
        if not cv2.imwrite(tmp, image):
            raise OutputError(f"{p}: OpenCV could not write the image")
        os.replace(tmp, p)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


# ---- records that cannot be measured -------------------------------------------------------------


class RecordError(DetectionError):
    """A record's image files are missing or unreadable."""


def check_on_error(on_error: str) -> None:
    """Refuse an ``on_error`` that is not one of :data:`ON_ERROR` (``ConfigurationError``)."""
    if on_error not in ON_ERROR:
        raise ConfigurationError(f"on_error must be one of {ON_ERROR}, got {on_error!r}")


def report_problem(problem: Cpc2UrdfError, on_error: str, problems: list[str]) -> None:
    """Raise ``problem`` (``on_error="stop"``) or add its message to ``problems``."""
    if on_error == "stop":
        raise problem
    problems.append(str(problem))


__all__ = [
    "IMAGE_EXTENSIONS",
    "ON_ERROR",
    "RecordError",
    "check_on_error",
    "find_image",
    "read_grey",
    "report_problem",
    "write_image",
]
