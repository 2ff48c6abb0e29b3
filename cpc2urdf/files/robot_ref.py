"""One resolver for "which robot": a shipped name, a robot spec, a model file or a URDF.

Every command and API function that accepts a robot goes through :func:`load_robot`, so a name or
path means the same thing everywhere: a measurement file's ``"robot"``, ``--robot``, ``export``,
``check``, ``gaze``, ``view``, ``simulate``. A relative path inside a file is tried against that
file's folder first (``relative_to``).

A path ending in ``.urdf``, or any other file whose text is XML (not ``.json``), is read as a
URDF (:mod:`cpc2urdf.urdf.robot`): its tree is the robot, every link reachable from the root
through calibratable joints a frame; a measurement file then restricts it to the sub-tree of the
links it measures.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path

from cpc2urdf.errors import InputFileError
from cpc2urdf.files.jsonio import read_json
from cpc2urdf.files.model_file import MODEL_FORMAT, model_from_json
from cpc2urdf.files.spec import ROBOT_FORMAT, RobotSpec, spec_from_json
from cpc2urdf.model import CPCModel
from cpc2urdf.urdf.robot import load_urdf_robot

RobotRef = str | os.PathLike[str] | RobotSpec


def shipped_robots() -> list[str]:
    """Names of the robots installed with the package (``iis_head``, ...)."""
    from cpc2urdf.robots import available

    return available()


def looks_like_path(ref: str) -> bool:
    """True if ``ref`` is written as a file path rather than a shipped robot name."""
    return "/" in ref or os.sep in ref or Path(ref).suffix != ""


def is_urdf_ref(ref: str | os.PathLike[str]) -> bool:
    """True if ``ref`` names a URDF file: a ``.urdf`` suffix (any case), or an existing file
    not named ``.json`` whose text starts with ``<`` (XML: a URDF saved as ``.xml``, or with no
    suffix, is read as one, not refused as 'not valid JSON')."""
    path = Path(os.fspath(ref))
    if path.suffix.lower() == ".urdf":
        return True
    if path.suffix.lower() == ".json" or not path.is_file():
        return False
    try:
        with open(path, "rb") as f:
            head = f.read(512)
    except OSError:
        return False  # reading it again names the problem
    return head.removeprefix(b"\xef\xbb\xbf").lstrip().startswith(b"<")


def load_robot(ref: RobotRef, *, relative_to: str | os.PathLike[str] | None = None) -> RobotSpec:
    """The robot ``ref`` refers to.

    Args:
        ref: A :class:`~cpc2urdf.files.spec.RobotSpec` (returned as is), a shipped robot name (e.g.
            ``"iis_head"``), or the path of a robot spec (``cpc2urdf/robot@1``), model file
            (``cpc2urdf/model@1``; its model becomes the spec's nominal model) or URDF (``.urdf``,
            or XML text in a file not named ``.json``: :func:`is_urdf_ref`; a
            :class:`~cpc2urdf.urdf.robot.UrdfRobot` whose nominal model remembers the file).
        relative_to: Folder against which a relative path is tried first (the folder of the file
            that named the robot).

    Raises:
        InputFileError: Naming the reference: not a shipped name and no such file, or a file of
            another format, or a file that does not parse (for a URDF: the element and its line).
    """
    if isinstance(ref, RobotSpec):
        return ref
    text = os.fspath(ref)
    if not text:
        raise InputFileError(
            "<robot>", "empty robot reference; expected a shipped robot name or a file path"
        )
    if not looks_like_path(text) and not os.path.exists(text):
        from cpc2urdf.robots import spec_path

        shipped = spec_path(text)
        if shipped is None:
            raise InputFileError(
                text, f"no such file, and not a shipped robot name ({', '.join(shipped_robots())})"
            )
        return spec_from_json(read_json(shipped), text)
    path = Path(text)
    if relative_to is not None and not path.is_absolute() and (Path(relative_to) / path).exists():
        path = Path(relative_to) / path
    if not path.exists():
        raise InputFileError(
            text, f"no such file, and not a shipped robot name ({', '.join(shipped_robots())})"
        )
    if is_urdf_ref(path):
        return load_urdf_robot(path)
    doc = read_json(path)
    fmt = doc.get("format") if isinstance(doc, Mapping) else None
    if fmt == MODEL_FORMAT:
        model = model_from_json(doc, str(path))
        return RobotSpec(model.structure, model, str(path))
    if fmt == ROBOT_FORMAT:
        return spec_from_json(doc, str(path))
    raise InputFileError(
        str(path),
        f"format is {fmt!r}, expected {MODEL_FORMAT!r} or {ROBOT_FORMAT!r} "
        f"(or a shipped robot name: {', '.join(shipped_robots())})",
    )


def load_model(ref: RobotRef, *, relative_to: str | os.PathLike[str] | None = None) -> CPCModel:
    """A model: a model file, or the nominal model of a robot spec, URDF or shipped robot."""
    return load_robot(ref, relative_to=relative_to).nominal_model()


__all__ = [
    "RobotRef",
    "is_urdf_ref",
    "load_model",
    "load_robot",
    "looks_like_path",
    "shipped_robots",
]
