"""The input mistakes the hand-eye consistency gate tests, each with the function that undoes it.

Every mistake is a way in which a user's ``T_base_hand`` / ``T_camera_target`` lists (shape
(N, 4, 4), metres, conventions of :mod:`cpc2urdf.identification.handeye.axxb`) can differ from
what the equation ``A X = Z B`` needs. :func:`~cpc2urdf.identification.handeye.gate.handeye_gate.check_consistency`
undoes each one in turn, solves again and compares: the mistake whose undoing explains the data
is the one it names. ``undo`` returns the repaired lists and the indices of the records it kept
(a pairing shifted by one loses a record).

Two mistakes are exact symmetries and can only be told apart by physical plausibility: inverting
*both* lists maps the solution ``(X, Z)`` to ``(Z, X)``, and scaling *both* lists' lengths scales
``X`` and ``Z``; undoing one list's inversion fits exactly as well as undoing the other's (and one
list's length scale as well as the inverse scale of the other). ``symmetric`` marks the first kind.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from cpc2urdf.transforms import Array, inverse

Undo = Callable[[Array, Array], tuple[Array, Array, NDArray[np.intp]]]


@dataclass(frozen=True)
class Mistake:
    """One way the input can be wrong.

    Attributes:
        code: Short machine name (stored in the model's hand-eye record).
        cause: What the user did, in words (the refusal names it).
        fix: What to change in the input.
        undo: ``(T_base_hand, T_camera_target) -> (T_base_hand', T_camera_target', kept)``: the
            lists as they should have been, and the indices of the records kept.
        symmetric: Undoing it fits exactly as well as the data as given (only plausibility can
            tell): both lists inverted, both lists' lengths scaled.
    """

    code: str
    cause: str
    fix: str
    undo: Undo
    symmetric: bool = False


def _all(n: int) -> NDArray[np.intp]:
    return np.arange(n, dtype=np.intp)


def _inverted(hand: bool, camera: bool) -> Undo:
    def undo(H: Array, C: Array) -> tuple[Array, Array, NDArray[np.intp]]:
        return (inverse(H) if hand else H), (inverse(C) if camera else C), _all(len(H))

    return undo


def _transpose_rotations(T: Array) -> Array:
    out = T.copy()
    out[:, :3, :3] = np.swapaxes(T[:, :3, :3], -1, -2)
    return out


def _transposed(hand: bool, camera: bool) -> Undo:
    def undo(H: Array, C: Array) -> tuple[Array, Array, NDArray[np.intp]]:
        return (
            (_transpose_rotations(H) if hand else H),
            (_transpose_rotations(C) if camera else C),
            _all(len(H)),
        )

    return undo


def _scale_lengths(T: Array, factor: float) -> Array:
    out = T.copy()
    out[:, :3, 3] *= factor
    return out


def _scaled(hand: float, camera: float) -> Undo:
    def undo(H: Array, C: Array) -> tuple[Array, Array, NDArray[np.intp]]:
        return _scale_lengths(H, hand), _scale_lengths(C, camera), _all(len(H))

    return undo


def rotation_from_wxyz_read_as_xyzw(R: Array) -> Array:
    """The rotations (N, 3, 3) meant by quaternions written ``w, x, y, z`` into a ``quat_xyzw`` field.

    The file's ``[a, b, c, d]`` was read as ``(x, y, z, w) = (a, b, c, d)``; the writer meant
    ``(w, x, y, z) = (a, b, c, d)``, i.e. ``(x, y, z, w) = (b, c, d, a)``. Recoverable from the
    rotation alone: ``-q`` gives the same rotation and maps to ``-q`` of the meant one.
    """
    q = Rotation.from_matrix(R).as_quat()  # (x, y, z, w) as read
    return Rotation.from_quat(np.roll(q, -1, axis=-1)).as_matrix()


def _quaternions(hand: bool, camera: bool) -> Undo:
    def fix(T: Array) -> Array:
        out = T.copy()
        out[:, :3, :3] = rotation_from_wxyz_read_as_xyzw(T[:, :3, :3])
        return out

    def undo(H: Array, C: Array) -> tuple[Array, Array, NDArray[np.intp]]:
        return (fix(H) if hand else H), (fix(C) if camera else C), _all(len(H))

    return undo


def _shifted(step: int) -> Undo:
    """Hand pose k belongs with camera pose ``k + step``."""

    def undo(H: Array, C: Array) -> tuple[Array, Array, NDArray[np.intp]]:
        n = len(H)
        kept = np.arange(max(0, -step), n - max(0, step), dtype=np.intp)
        return H[kept], C[kept + step], kept

    return undo


_INVERT_HAND = "invert T_base_hand (give the hand pose in the robot base frame)"
_INVERT_CAMERA = (
    "invert T_camera_target (give the target pose in the camera frame: solvePnP's rvec/tvec)"
)

MISTAKES: tuple[Mistake, ...] = (
    Mistake(
        "hand_inverted",
        "inconsistent directions: hand poses inverted (T_hand_base given instead of T_base_hand)",
        _INVERT_HAND,
        _inverted(True, False),
    ),
    Mistake(
        "camera_inverted",
        "inconsistent directions: camera poses inverted (T_target_camera given instead of T_camera_target)",
        _INVERT_CAMERA,
        _inverted(False, True),
    ),
    Mistake(
        "both_inverted",
        "inconsistent directions: both pose lists inverted (T_hand_base and T_target_camera given)",
        "invert both lists",
        _inverted(True, True),
        symmetric=True,
    ),
    Mistake(
        "hand_transposed",
        "hand rotation blocks transposed (R^T in T_base_hand)",
        "transpose the rotation part of every T_base_hand",
        _transposed(True, False),
    ),
    Mistake(
        "camera_transposed",
        "camera rotation blocks transposed (R^T in T_camera_target)",
        "transpose the rotation part of every T_camera_target",
        _transposed(False, True),
    ),
    Mistake(
        "both_transposed",
        "rotation blocks transposed in both pose lists",
        "transpose the rotation part of every pose",
        _transposed(True, True),
    ),
    Mistake(
        "hand_lengths_small",
        "hand-pose lengths 1000x too small (metres in a file that says mm?)",
        "give T_base_hand's lengths in the file's unit",
        _scaled(1e3, 1.0),
    ),
    Mistake(
        "hand_lengths_large",
        "hand-pose lengths 1000x too large (millimetres in a file that says m?)",
        "give T_base_hand's lengths in the file's unit",
        _scaled(1e-3, 1.0),
    ),
    Mistake(
        "camera_lengths_small",
        "camera-pose lengths 1000x too small (metres in a file that says mm?)",
        "give T_camera_target's lengths in the file's unit",
        _scaled(1.0, 1e3),
    ),
    Mistake(
        "camera_lengths_large",
        "camera-pose lengths 1000x too large (millimetres in a file that says m?)",
        "give T_camera_target's lengths in the file's unit",
        _scaled(1.0, 1e-3),
    ),
    Mistake(
        "lengths_small",
        "all lengths 1000x too small (metres in a file that says mm?)",
        "state the file's length unit correctly",
        _scaled(1e3, 1e3),
        symmetric=True,
    ),
    Mistake(
        "lengths_large",
        "all lengths 1000x too large (millimetres in a file that says m, or no units?)",
        "state the file's length unit correctly",
        _scaled(1e-3, 1e-3),
        symmetric=True,
    ),
    Mistake(
        "paired_next",
        "poses paired off by one (each record's camera pose belongs to the next record's hand pose)",
        "pair every hand pose with the camera pose taken at the same configuration",
        _shifted(-1),
    ),
    Mistake(
        "paired_previous",
        "poses paired off by one (each record's camera pose belongs to the previous record's hand pose)",
        "pair every hand pose with the camera pose taken at the same configuration",
        _shifted(1),
    ),
    Mistake(
        "hand_quaternion_order",
        "hand quaternions written w,x,y,z where quat_xyzw (x,y,z,w) is expected",
        "write T_base_hand's quaternions as x, y, z, w",
        _quaternions(True, False),
    ),
    Mistake(
        "camera_quaternion_order",
        "camera quaternions written w,x,y,z where quat_xyzw (x,y,z,w) is expected",
        "write T_camera_target's quaternions as x, y, z, w",
        _quaternions(False, True),
    ),
)
MISTAKE_CODES = tuple(m.code for m in MISTAKES)


def mistake(code: str) -> Mistake:
    """The mistake named ``code`` (one of :data:`MISTAKE_CODES`)."""
    return next(m for m in MISTAKES if m.code == code)


__all__ = ["MISTAKES", "MISTAKE_CODES", "Mistake", "mistake", "rotation_from_wxyz_read_as_xyzw"]
