"""Hand-eye pose files (``cpc2urdf/handeye-poses@1``): pairs of hand and target poses.

On disk::

    {"format": "cpc2urdf/handeye-poses@1",
     "units": {"length": "mm", "angle": "deg"},   # optional, default m/rad (angle: for "rpy")
     "description": "...",                        # optional, free text
     "camera": "camera_left_optical",             # optional: which camera (free text)
     "hand": "plate_left",                        # optional: which hand frame (free text)
     "noise": {"T_base_hand": {"position": 0.05, "angle": 0.01},          # optional: std per
               "T_camera_target": {"position": 0.3, "angle": 0.05}},    # axis, file units
     "records": [
       {"label": "q0",                                            # optional
        "T_base_hand": {"matrix": [[...], [...], [...], [0, 0, 0, 1]]},
        "T_camera_target": {"xyz": [x, y, z], "quat_xyzw": [qx, qy, qz, qw]}},
       ...
     ]}

``T_base_hand`` is the pose of the hand (the frame the camera is mounted on) in the robot base
frame, from the robot's kinematics. ``T_camera_target`` is the pose of the calibration target in
the camera's optical frame, as ``cv2.solvePnP`` returns it (``rvec, tvec``: target points to
camera coordinates). Each pose is a 4x4 ``matrix`` or ``xyz`` + ``quat_xyzw`` (or ``xyz`` +
``rpy``), see :mod:`cpc2urdf.files.poses`. ``noise`` (optional, :class:`~cpc2urdf.identification.handeye.pose_noise.PoseNoise`)
is what the consistency gate tests the residuals against. Documented in ``docs/handeye.md``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from cpc2urdf.errors import InputFileError
from cpc2urdf.files.jsonio import read_json, require_format, write_json
from cpc2urdf.files.poses import pose_from_json, pose_to_json
from cpc2urdf.files.units import Units
from cpc2urdf.identification.handeye.pose_noise import PoseNoise
from cpc2urdf.identification.handeye.streams import StreamPairing
from cpc2urdf.transforms import Array

HANDEYE_POSES_FORMAT = "cpc2urdf/handeye-poses@1"
_TOP_KEYS = {"format", "units", "description", "camera", "hand", "noise", "records", "provenance"}
_RECORD_KEYS = {"label", "T_base_hand", "T_camera_target"}


@dataclass(frozen=True)
class HandEyePoses:
    """Paired poses for hand-eye calibration, in SI units.

    Attributes:
        T_base_hand: Hand poses in the base frame, shape (N, 4, 4) [m].
        T_camera_target: Target poses in the camera frame, shape (N, 4, 4) [m].
        labels: One label per record.
        camera: Name of the camera, or "".
        hand: Name of the hand frame, or "".
        source: Where the poses came from (a file path, or ``"<memory>"``); errors name it.
        noise: The noise the file states, or None (the consistency gate then estimates it).
        pairing: How pose streams became these pairs (clock offset, frames, keyframes), or None
            for a pose file (:mod:`cpc2urdf.identification.handeye.stream_files`).
    """

    T_base_hand: Array
    T_camera_target: Array
    labels: tuple[str, ...]
    camera: str = ""
    hand: str = ""
    source: str = "<memory>"
    noise: PoseNoise | None = None
    pairing: StreamPairing | None = None


def handeye_poses_from_json(doc: Any, source: str = "<handeye poses>") -> HandEyePoses:
    """Parse a ``cpc2urdf/handeye-poses@1`` document.

    Raises:
        InputFileError: Naming ``source``, the record and the field.
    """
    try:
        d = require_format(doc, HANDEYE_POSES_FORMAT, source)
        unknown = set(d) - _TOP_KEYS
        if unknown:
            raise ValueError(
                f"unknown keys {sorted(unknown)}; expected some of {sorted(_TOP_KEYS)}"
            )
        units = Units.from_json(d.get("units"))
        noise = PoseNoise.from_json(d["noise"], units) if "noise" in d else None
        records = d.get("records")
        if not isinstance(records, list) or not records:
            raise ValueError(
                "'records' must be a non-empty list of {T_base_hand, T_camera_target} records"
            )
        H, C, labels = [], [], []
        for i, rec in enumerate(records):
            where = f"records[{i}]"
            if not isinstance(rec, Mapping):
                raise ValueError(
                    f"{where} must be an object with 'T_base_hand' and 'T_camera_target'"
                )
            extra = set(rec) - _RECORD_KEYS
            if extra:
                hint = ""
                if extra & {"T_target_camera", "T_hand_base", "T_camera_hand", "T_hand_camera"}:
                    hint = " (give T_base_hand and T_camera_target; invert the poses you have)"
                raise ValueError(
                    f"{where} has unknown keys {sorted(extra)}; expected {sorted(_RECORD_KEYS)}{hint}"
                )
            for key in ("T_base_hand", "T_camera_target"):
                if key not in rec:
                    raise ValueError(f"{where} lacks {key!r}")
            H.append(pose_from_json(rec["T_base_hand"], units, f"{where}.T_base_hand"))
            C.append(pose_from_json(rec["T_camera_target"], units, f"{where}.T_camera_target"))
            labels.append(str(rec.get("label", f"pose {i}")))
        for key in ("camera", "hand"):
            if key in d and not isinstance(d[key], str):
                raise ValueError(f"'{key}' must be a string, got {d[key]!r}")
        _refuse_copies(H, C)
        return HandEyePoses(
            np.array(H),
            np.array(C),
            tuple(labels),
            d.get("camera", ""),
            d.get("hand", ""),
            source,
            noise,
        )
    except InputFileError:
        raise
    except ValueError as e:
        raise InputFileError(source, str(e)) from e


def _refuse_copies(H: list[Array], C: list[Array]) -> None:
    """A record whose two poses repeat an earlier record's to the last digit is a copy (a file
    concatenated with itself, a line pasted twice): a measurement taken again differs in its noise,
    and a copy would count one pose twice in the solve."""
    first: dict[bytes, int] = {}
    copies: list[tuple[int, int]] = []
    for i, (h, c) in enumerate(zip(H, C, strict=True)):
        key = np.concatenate([h.ravel(), c.ravel()]).tobytes()
        if key in first:
            copies.append((i, first[key]))
        else:
            first[key] = i
    if copies:
        i, j = copies[0]
        more = f" (and {len(copies) - 1} more copies)" if len(copies) > 1 else ""
        raise ValueError(
            f"records[{i}] repeats records[{j}] to the last digit (T_base_hand and T_camera_target)"
            f"{more}: a copied record, not a new measurement; remove the "
            f"{len(copies)} {'copy' if len(copies) == 1 else 'copies'}"
        )


def load_handeye_poses(path: str | os.PathLike[str]) -> HandEyePoses:
    """Read a pose file; :class:`InputFileError` names the file, record and field on any problem."""
    return handeye_poses_from_json(read_json(path), str(path))


def handeye_poses_to_json(
    T_base_hand: ArrayLike,
    T_camera_target: ArrayLike,
    *,
    labels: Sequence[str] | None = None,
    camera: str = "",
    hand: str = "",
    units: Units | None = None,
    description: str = "",
    noise: PoseNoise | None = None,
) -> dict[str, Any]:
    """A ``cpc2urdf/handeye-poses@1`` document (poses as matrices, lengths and noise in ``units``)."""
    u = units or Units()
    H = np.asarray(T_base_hand, dtype=float)
    C = np.asarray(T_camera_target, dtype=float)
    doc: dict[str, Any] = {"format": HANDEYE_POSES_FORMAT, "units": u.to_json()}
    if description:
        doc["description"] = description
    if camera:
        doc["camera"] = camera
    if hand:
        doc["hand"] = hand
    if noise is not None:
        doc["noise"] = noise.to_json(u)
    doc["records"] = [
        {
            "label": labels[k] if labels else f"pose {k}",
            "T_base_hand": pose_to_json(H[k], u),
            "T_camera_target": pose_to_json(C[k], u),
        }
        for k in range(len(H))
    ]
    return doc


def save_handeye_poses(
    path: str | os.PathLike[str],
    T_base_hand: ArrayLike,
    T_camera_target: ArrayLike,
    *,
    labels: Sequence[str] | None = None,
    camera: str = "",
    hand: str = "",
    units: Units | None = None,
    description: str = "",
    noise: PoseNoise | None = None,
) -> Path:
    """Write a pose file atomically; keyword arguments as :func:`handeye_poses_to_json`."""
    return write_json(
        path,
        handeye_poses_to_json(
            T_base_hand,
            T_camera_target,
            labels=labels,
            camera=camera,
            hand=hand,
            units=units,
            description=description,
            noise=noise,
        ),
    )


__all__ = [
    "HANDEYE_POSES_FORMAT",
    "HandEyePoses",
    "handeye_poses_from_json",
    "handeye_poses_to_json",
    "load_handeye_poses",
    "save_handeye_poses",
]
