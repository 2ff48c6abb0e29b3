"""The hand-eye input mistakes a user makes, applied to a clean pose file (``cpc2urdf/handeye-poses@1``).

:func:`clean_document` is a seeded, noisy, consistent set of poses in mm and deg with matrix poses
(the camera 0.14 m from the hand, the target about 1 m from the base and the camera). Each function
of :data:`MISTAKES` returns a broken deep copy: what a user's file looks like after that mistake,
with the code the consistency gate must name (``ConsistencyReport.code``) and words its one-line
refusal must contain.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from cpc2urdf.files.units import Units
from cpc2urdf.identification.handeye.pose_file import handeye_poses_to_json
from cpc2urdf.transforms import homogeneous, inverse, matrix_from_rpy

Doc = dict[str, Any]

X_TRUE = homogeneous(
    matrix_from_rpy(np.radians([10.0, -20.0, 30.0])), [0.030, 0.050, 0.120]
)  # T_hand_camera
Z_TRUE = homogeneous(
    matrix_from_rpy(np.radians([5.0, 10.0, 120.0])), [0.800, -0.300, 0.400]
)  # T_base_target
HAND_NOISE = (math.radians(0.02), 0.0001)  # (angle [rad], position [m]) per axis
CAMERA_NOISE = (math.radians(0.05), 0.0003)
OUTLIERS = (3, 8)


def _perturb(rng: np.random.Generator, T: np.ndarray, angle: float, position: float) -> np.ndarray:
    out = T.copy()
    for k in range(len(T)):
        out[k, :3, :3] = Rotation.from_rotvec(rng.normal(0.0, angle, 3)).as_matrix() @ T[k, :3, :3]
        out[k, :3, 3] += rng.normal(0.0, position, 3)
    return out


def clean_poses(seed: int = 0, n: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """``(T_base_hand, T_camera_target)`` [m], shape (n, 4, 4) each, with the noise above."""
    rng = np.random.default_rng(seed)
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = rng.uniform(math.radians(10.0), math.radians(150.0), n)
    H = np.array(
        [
            homogeneous(Rotation.from_rotvec(a * t).as_matrix(), rng.uniform(-0.5, 0.5, 3))
            for a, t in zip(axes, angles, strict=True)
        ]
    )
    C = inverse(X_TRUE)[None] @ inverse(H) @ Z_TRUE[None]
    return _perturb(rng, H, *HAND_NOISE), _perturb(rng, C, *CAMERA_NOISE)


def clean_document(seed: int = 0, n: int = 12) -> Doc:
    """The clean pose file (mm, deg, matrices), camera ``camera_left_optical`` on hand ``plate_left``."""
    H, C = clean_poses(seed, n)
    return handeye_poses_to_json(
        H,
        C,
        labels=[f"config {k}" for k in range(n)],
        camera="camera_left_optical",
        hand="plate_left",
        units=Units("mm", "deg"),
    )


def _map(doc: Doc, key: str, fn: Callable[[np.ndarray], Any]) -> Doc:
    d = copy.deepcopy(doc)
    for rec in d["records"]:
        rec[key] = fn(np.array(rec[key]["matrix"], dtype=float))
    return d


def _matrix(T: np.ndarray) -> dict[str, Any]:
    return {"matrix": T.tolist()}


def _transposed(T: np.ndarray) -> dict[str, Any]:
    out = T.copy()
    out[:3, :3] = T[:3, :3].T
    return _matrix(out)


def _metres(T: np.ndarray) -> dict[str, Any]:  # a pose in m written into a file that says mm
    out = T.copy()
    out[:3, 3] *= 1e-3
    return _matrix(out)


def _millimetres(T: np.ndarray) -> dict[str, Any]:  # a pose in mm written into a file that says m
    out = T.copy()
    out[:3, 3] *= 1e3
    return _matrix(out)


def _wxyz(T: np.ndarray) -> dict[str, Any]:  # the quaternion written w, x, y, z into quat_xyzw
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    return {"xyz": T[:3, 3].tolist(), "quat_xyzw": [w, x, y, z]}


def hand_inverted(doc: Doc) -> Doc:
    return _map(doc, "T_base_hand", lambda T: _matrix(inverse(T)))


def camera_inverted(doc: Doc) -> Doc:
    return _map(doc, "T_camera_target", lambda T: _matrix(inverse(T)))


def both_inverted(doc: Doc) -> Doc:
    return camera_inverted(hand_inverted(doc))


def hand_transposed(doc: Doc) -> Doc:
    return _map(doc, "T_base_hand", _transposed)


def camera_transposed(doc: Doc) -> Doc:
    return _map(doc, "T_camera_target", _transposed)


def hand_metres_in_mm_file(doc: Doc) -> Doc:
    return _map(doc, "T_base_hand", _metres)


def camera_metres_in_mm_file(doc: Doc) -> Doc:
    return _map(doc, "T_camera_target", _metres)


def camera_mm_in_m_file(doc: Doc) -> Doc:
    """The file says m (hand poses converted), the camera poses stayed in mm."""
    d = _map(doc, "T_base_hand", _metres)
    d["units"] = {"length": "m", "angle": "deg"}
    return d


def paired_off_by_one(doc: Doc) -> Doc:
    """Each record holds the next record's camera pose (the camera list starts one late)."""
    d = copy.deepcopy(doc)
    recs = d["records"]
    for k in range(len(recs) - 1):
        recs[k]["T_camera_target"] = copy.deepcopy(doc["records"][k + 1]["T_camera_target"])
    d["records"] = recs[:-1]
    return d


def hand_quaternions_wxyz(doc: Doc) -> Doc:
    return _map(doc, "T_base_hand", _wxyz)


def camera_quaternions_wxyz(doc: Doc) -> Doc:
    return _map(doc, "T_camera_target", _wxyz)


def outliers(doc: Doc) -> Doc:
    """Two target detections gone wrong: rotated by 5 deg and shifted by 20 mm."""
    d = copy.deepcopy(doc)
    for k in OUTLIERS:
        T = np.array(d["records"][k]["T_camera_target"]["matrix"], dtype=float)
        T[:3, :3] = Rotation.from_rotvec([0.0, math.radians(5.0), 0.0]).as_matrix() @ T[:3, :3]
        T[:3, 3] += [20.0, 0.0, 0.0]  # mm
        d["records"][k]["T_camera_target"] = _matrix(T)
    return d


#: ``(mistake, code the gate names, words the refusal contains)``; :func:`outliers` is not one:
#: the poses are dropped and named, and the answer given without them.
MISTAKES: tuple[tuple[Callable[[Doc], Doc], str, str], ...] = (
    (
        hand_inverted,
        "hand_inverted",
        "hand poses inverted (T_hand_base given instead of T_base_hand)",
    ),
    (
        camera_inverted,
        "camera_inverted",
        "camera poses inverted (T_target_camera given instead of T_camera_target)",
    ),
    (both_inverted, "both_inverted", "both pose lists inverted"),
    (hand_transposed, "hand_transposed", "hand rotation blocks transposed"),
    (camera_transposed, "camera_transposed", "camera rotation blocks transposed"),
    (hand_metres_in_mm_file, "hand_lengths_small", "hand-pose lengths 1000x too small"),
    (camera_metres_in_mm_file, "camera_lengths_small", "camera-pose lengths 1000x too small"),
    (camera_mm_in_m_file, "camera_lengths_large", "camera-pose lengths 1000x too large"),
    (paired_off_by_one, "paired_next", "poses paired off by one"),
    (hand_quaternions_wxyz, "hand_quaternion_order", "hand quaternions written w,x,y,z"),
    (camera_quaternions_wxyz, "camera_quaternion_order", "camera quaternions written w,x,y,z"),
)
