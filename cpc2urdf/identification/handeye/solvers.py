"""One registry of every hand-eye solver, and one way to run any of them.

Every solver takes the same absolute poses -- ``T_base_hand`` and ``T_camera_target``, shape
(N, 4, 4) [m], conventions of :mod:`cpc2urdf.identification.handeye.axxb` -- and returns
``X = T_hand_camera`` and ``Z = T_base_target``:

- ``A X = X B`` (:mod:`~cpc2urdf.identification.handeye.axxb`): ``tsai``, ``park_martin``,
  ``daniilidis`` solve X from the all-pairs relative motions; Z is then the chordal mean of
  ``T_base_hand[k] X T_camera_target[k]``;
- ``A X = Z B`` (:mod:`~cpc2urdf.identification.handeye.axzb`): ``kronecker``,
  ``dual_quaternion``, ``zhuang``, ``refined`` solve X and Z together from ``A_k = T_base_hand[k]``,
  ``B_k = inv(T_camera_target[k])``.

:func:`calibrate` validates the poses, refuses degenerate data
(:func:`~cpc2urdf.identification.handeye.axxb.diagnose`, plus a solver's own check), solves and
returns a :class:`~cpc2urdf.identification.handeye.axxb.HandEyeResult` with per-pose residuals
and warnings. :func:`calibrate_hand_eye` and :func:`calibrate_robot_world` do the same restricted
to one equation's solvers.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from numpy.typing import ArrayLike

from cpc2urdf.identification.handeye.axxb import (
    HandEyeResult,
    as_pose_stack,
    diagnose,
    make_result,
    relative_motions,
    solve_daniilidis,
    solve_park_martin,
    solve_tsai,
    target_from_x,
)
from cpc2urdf.identification.handeye.axzb import (
    solve_dual_quaternion,
    solve_kronecker,
    solve_refined,
    solve_zhuang,
    zhuang_a0_check,
)
from cpc2urdf.transforms import Array, inverse

AX_XB = "AX = XB"
AX_ZB = "AX = ZB"


@dataclass(frozen=True)
class HandEyeSolver:
    """A registered solver.

    Attributes:
        name: Method name (``--method`` of ``cpc2urdf handeye``).
        equation: :data:`AX_XB` or :data:`AX_ZB`.
        description: One line: equation and reference.
        solve: ``(T_base_hand, T_camera_target) -> (X, Z)`` on validated absolute poses, each
            shape (N, 4, 4) [m]; X and Z shape (4, 4).
        check: Extra data check on ``T_base_hand`` (N, 4, 4): raises ``DegenerateDataError``
            or returns warnings; None if the solver has none.
    """

    name: str
    equation: str
    description: str
    solve: Callable[[Array, Array], tuple[Array, Array]]
    check: Callable[[Array], list[str]] | None = None


def _from_relative_motions(solve_x: Callable[[Array, Array], Array]) -> Callable[[Array, Array], tuple[Array, Array]]:
    """An ``A X = X B`` solver of relative motions as a solver of absolute poses: X, then Z."""

    def solve(T_base_hand: Array, T_camera_target: Array) -> tuple[Array, Array]:
        A, B = relative_motions(T_base_hand, T_camera_target)
        X = solve_x(A, B)
        return X, target_from_x(T_base_hand, T_camera_target, X)

    return solve


def _from_absolute_poses(solve_xz: Callable[[Array, Array], tuple[Array, Array]]) -> Callable[[Array, Array], tuple[Array, Array]]:
    """An ``A X = Z B`` solver as a solver of ``(T_base_hand, T_camera_target)``: ``B = inv(C)``."""

    def solve(T_base_hand: Array, T_camera_target: Array) -> tuple[Array, Array]:
        return solve_xz(T_base_hand, inverse(T_camera_target))

    return solve


SOLVERS: dict[str, HandEyeSolver] = {
    s.name: s
    for s in (
        HandEyeSolver("tsai", AX_XB, "AX = XB, Tsai & Lenz 1989", _from_relative_motions(solve_tsai)),
        HandEyeSolver("park_martin", AX_XB, "AX = XB, Park & Martin 1994", _from_relative_motions(solve_park_martin)),
        HandEyeSolver("daniilidis", AX_XB, "AX = XB, Daniilidis 1999 (dual quaternions)",
                      _from_relative_motions(solve_daniilidis)),
        HandEyeSolver("kronecker", AX_ZB, "AX = ZB, Li et al. 2010 (Kronecker product)",
                      _from_absolute_poses(solve_kronecker)),
        HandEyeSolver("dual_quaternion", AX_ZB, "AX = ZB, Li et al. 2010 (dual quaternions)",
                      _from_absolute_poses(solve_dual_quaternion)),
        HandEyeSolver("zhuang", AX_ZB, "AX = ZB, Zhuang et al. 1994 (quaternions, two stages)",
                      _from_absolute_poses(solve_zhuang), zhuang_a0_check),
        HandEyeSolver("refined", AX_ZB, "AX = ZB, Kronecker start + joint nonlinear least squares",
                      _from_absolute_poses(solve_refined)),
    )
}
HAND_EYE_METHODS = tuple(n for n, s in SOLVERS.items() if s.equation == AX_XB)
ROBOT_WORLD_METHODS = tuple(n for n, s in SOLVERS.items() if s.equation == AX_ZB)
ALL_METHODS = HAND_EYE_METHODS + ROBOT_WORLD_METHODS
#: The solver used when none is named (``cpc2urdf handeye``, the API): Li et al.'s Kronecker method.
DEFAULT_HANDEYE_METHOD = "kronecker"


def _run(
    T_base_hand: ArrayLike, T_camera_target: ArrayLike, method: str, methods: Sequence[str], kind: str
) -> HandEyeResult:
    """Validate, diagnose and solve with ``SOLVERS[method]``, which must be one of ``methods``."""
    if method not in methods:
        raise ValueError(f"unknown {kind}method {method!r}; known: {', '.join(methods)}")
    solver = SOLVERS[method]
    H = as_pose_stack(T_base_hand, "T_base_hand")
    C = as_pose_stack(T_camera_target, "T_camera_target")
    warnings = diagnose(H, C)
    if solver.check is not None:
        warnings += solver.check(H)
    X, Z = solver.solve(H, C)
    return make_result(method, H, C, X, Z, warnings)


def calibrate(T_base_hand: ArrayLike, T_camera_target: ArrayLike, method: str) -> HandEyeResult:
    """Solve for ``X = T_hand_camera`` and ``Z = T_base_target`` with any solver of :data:`ALL_METHODS`.

    Args:
        T_base_hand: Hand poses in the robot base frame, shape (N, 4, 4) [m].
        T_camera_target: Target poses in the camera frame (solvePnP), shape (N, 4, 4) [m].
        method: One of :data:`ALL_METHODS`.

    Returns:
        The solution with per-pose residuals and warnings.

    Raises:
        DegenerateDataError: See :func:`~cpc2urdf.identification.handeye.axxb.diagnose`, and hand
            rotations near 180 deg for ``zhuang``.
        ValueError: Malformed poses or an unknown method.
    """
    return _run(T_base_hand, T_camera_target, method, ALL_METHODS, "")


def calibrate_hand_eye(
    T_base_hand: ArrayLike, T_camera_target: ArrayLike, method: str = "tsai"
) -> HandEyeResult:
    """:func:`calibrate` restricted to the ``A X = X B`` solvers (:data:`HAND_EYE_METHODS`)."""
    return _run(T_base_hand, T_camera_target, method, HAND_EYE_METHODS, "AX=XB ")


def calibrate_robot_world(
    T_base_hand: ArrayLike, T_camera_target: ArrayLike, method: str = "kronecker"
) -> HandEyeResult:
    """:func:`calibrate` restricted to the ``A X = Z B`` solvers (:data:`ROBOT_WORLD_METHODS`)."""
    return _run(T_base_hand, T_camera_target, method, ROBOT_WORLD_METHODS, "AX=ZB ")


__all__ = [
    "DEFAULT_HANDEYE_METHOD",
    "ALL_METHODS",
    "AX_XB",
    "AX_ZB",
    "HAND_EYE_METHODS",
    "ROBOT_WORLD_METHODS",
    "SOLVERS",
    "HandEyeSolver",
    "calibrate",
    "calibrate_hand_eye",
    "calibrate_robot_world",
]
