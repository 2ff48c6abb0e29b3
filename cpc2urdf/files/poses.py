"""Poses in files: a 4x4 ``matrix``, or ``xyz`` + ``quat_xyzw`` (or ``xyz`` + ``rpy``).

All pose-carrying file formats (measurements, hand-eye poses, model frames) use these helpers, so
they accept and reject the same things the same way.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from cpc2urdf.files.jsonio import float_list
from cpc2urdf.files.units import Units
from cpc2urdf.tolerances import ROTATION_TOL
from cpc2urdf.transforms import Array, homogeneous, matrix_from_rpy, rotation_defect

POSE_KEYS = ("matrix", "xyz", "quat_xyzw", "rpy")


def pose_from_json(obj: Any, units: Units, where: str) -> Array:
    """Parse a pose object into a (4, 4) transform in SI units.

    Accepted forms (lengths in ``units.length``, ``rpy`` in ``units.angle``)::

        {"matrix": [[r11, r12, r13, x], [.., .., .., y], [.., .., .., z], [0, 0, 0, 1]]}
        {"xyz": [x, y, z], "quat_xyzw": [qx, qy, qz, qw]}
        {"xyz": [x, y, z], "rpy": [roll, pitch, yaw]}

    Raises:
        ValueError: naming ``where`` and the field: wrong shape, NaN, a non-orthonormal
            rotation (max |R^T R - I| > ROTATION_TOL), a quaternion far from unit length.
    """
    if not isinstance(obj, Mapping):
        raise ValueError(
            f"{where} must be an object with 'matrix' or 'xyz'+'quat_xyzw', got {obj!r}"
        )
    unknown = set(obj) - set(POSE_KEYS)
    if unknown:
        raise ValueError(
            f"{where} has unknown keys {sorted(unknown)}; expected one of {list(POSE_KEYS)}"
        )
    if "matrix" in obj:
        if set(obj) != {"matrix"}:
            raise ValueError(f"{where}: give either 'matrix' or 'xyz'+'quat_xyzw', not both")
        rows = obj["matrix"]
        if not isinstance(rows, list) or len(rows) != 4:
            raise ValueError(f"{where}.matrix must be 4 rows of 4 numbers")
        M = np.array([float_list(r, 4, f"{where}.matrix[{i}]") for i, r in enumerate(rows)])
        if np.max(np.abs(M[3] - [0.0, 0.0, 0.0, 1.0])) > 1e-12:
            raise ValueError(f"{where}.matrix last row must be [0, 0, 0, 1], got {M[3].tolist()}")
        R = M[:3, :3]
        defect = rotation_defect(R)
        if defect > ROTATION_TOL:
            raise ValueError(
                f"{where}.matrix rotation part is not orthonormal with det +1 "
                f"(defect {defect:.3g} > {ROTATION_TOL:g})"
            )
        return homogeneous(R, M[:3, 3] * units.length)
    if "xyz" not in obj:
        raise ValueError(f"{where} needs 'matrix', or 'xyz' with 'quat_xyzw' or 'rpy'")
    xyz = np.array(float_list(obj["xyz"], 3, f"{where}.xyz")) * units.length
    if ("quat_xyzw" in obj) == ("rpy" in obj):
        raise ValueError(f"{where} needs exactly one of 'quat_xyzw' and 'rpy' beside 'xyz'")
    if "quat_xyzw" in obj:
        q = np.array(float_list(obj["quat_xyzw"], 4, f"{where}.quat_xyzw"))
        n = float(np.linalg.norm(q))
        if abs(n - 1.0) > 1e-3:
            raise ValueError(f"{where}.quat_xyzw must be a unit quaternion, norm is {n:.6g}")
        R = Rotation.from_quat(q / n).as_matrix()
    else:
        rpy = np.array(float_list(obj["rpy"], 3, f"{where}.rpy")) * units.angle
        R = matrix_from_rpy(rpy)
    return homogeneous(R, xyz)


def pose_to_json(T: Array, units: Units | None = None) -> dict[str, Any]:
    """A (4, 4) transform as ``{"matrix": ...}`` in ``units`` (default SI), full precision."""
    u = units or Units()
    M = np.array(T, dtype=float)
    M[:3, 3] = M[:3, 3] / u.length
    return {"matrix": [[float(v) for v in row] for row in M]}


__all__ = [
    "POSE_KEYS",
    "pose_from_json",
    "pose_to_json",
]
