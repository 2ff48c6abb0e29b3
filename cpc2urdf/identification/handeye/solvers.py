"""One registry of every hand-eye solver, and one way to run any of them.

Every solver takes the same absolute poses -- ``T_base_hand`` and ``T_camera_target``, shape
(N, 4, 4) [m], conventions of :mod:`cpc2urdf.identification.handeye.axxb` -- and returns
``X = T_hand_camera`` and ``Z = T_base_target``:

- ``A X = X B`` (:mod:`~cpc2urdf.identification.handeye.axxb`): ``tsai``, ``park_martin``,
  ``daniilidis`` solve X from relative motions (all pairs up to 31 poses, 15 per pose beyond:
  :func:`~cpc2urdf.identification.handeye.axxb.motion_pairs`); Z is then the chordal mean of
  ``T_base_hand[k] X T_camera_target[k]``;
- ``A X = Z B`` (:mod:`~cpc2urdf.identification.handeye.axzb`): ``kronecker``,
  ``dual_quaternion``, ``zhuang``, ``refined`` solve X and Z together from ``A_k = T_base_hand[k]``,
  ``B_k = inv(T_camera_target[k])``.

:func:`calibrate` validates the poses, refuses degenerate data
(:func:`~cpc2urdf.identification.handeye.axxb.diagnose`, plus a solver's own check), solves and
returns a :class:`~cpc2urdf.identification.handeye.axxb.HandEyeResult` with per-pose residuals
and warnings. With ``gate=True`` (the API, the CLI and the stage-2 pipeline) the consistency gate
(:func:`~cpc2urdf.identification.handeye.gate.handeye_gate.check_consistency`) replaces the quick
direction check: data inconsistent with ``A X = Z B`` and their noise are refused with
:class:`~cpc2urdf.identification.handeye.gate.gate_report.InconsistentPosesError` naming the most
likely mistake, or kept with the diagnosis (``accept_inconsistent=True``).
:func:`calibrate_hand_eye` and :func:`calibrate_robot_world` do the same restricted to one
equation's solvers.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

from numpy.typing import ArrayLike

from cpc2urdf.identification.handeye.axxb import (
    HandEyeResult,
    as_pose_stack,
    check_degenerate,
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
from cpc2urdf.identification.handeye.gate.gate_report import (
    ConsistencyReport,
    InconsistentPosesError,
)
from cpc2urdf.identification.handeye.gate.handeye_gate import check_consistency
from cpc2urdf.identification.handeye.pose_file import HandEyePoses
from cpc2urdf.identification.handeye.pose_noise import PoseNoise
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


def _from_relative_motions(
    solve_x: Callable[[Array, Array], Array],
) -> Callable[[Array, Array], tuple[Array, Array]]:
    """An ``A X = X B`` solver of relative motions as a solver of absolute poses: X, then Z."""

    def solve(T_base_hand: Array, T_camera_target: Array) -> tuple[Array, Array]:
        A, B = relative_motions(T_base_hand, T_camera_target)
        X = solve_x(A, B)
        return X, target_from_x(T_base_hand, T_camera_target, X)

    return solve


def _from_absolute_poses(
    solve_xz: Callable[[Array, Array], tuple[Array, Array]],
) -> Callable[[Array, Array], tuple[Array, Array]]:
    """An ``A X = Z B`` solver as a solver of ``(T_base_hand, T_camera_target)``: ``B = inv(C)``."""

    def solve(T_base_hand: Array, T_camera_target: Array) -> tuple[Array, Array]:
        return solve_xz(T_base_hand, inverse(T_camera_target))

    return solve


SOLVERS: dict[str, HandEyeSolver] = {
    s.name: s
    for s in (
        HandEyeSolver(
            "tsai", AX_XB, "AX = XB, Tsai & Lenz 1989", _from_relative_motions(solve_tsai)
        ),
        HandEyeSolver(
            "park_martin",
            AX_XB,
            "AX = XB, Park & Martin 1994",
            _from_relative_motions(solve_park_martin),
        ),
        HandEyeSolver(
            "daniilidis",
            AX_XB,
            "AX = XB, Daniilidis 1999 (dual quaternions)",
            _from_relative_motions(solve_daniilidis),
        ),
        HandEyeSolver(
            "kronecker",
            AX_ZB,
            "AX = ZB, Li et al. 2010 (Kronecker product)",
            _from_absolute_poses(solve_kronecker),
        ),
        HandEyeSolver(
            "dual_quaternion",
            AX_ZB,
            "AX = ZB, Li et al. 2010 (dual quaternions)",
            _from_absolute_poses(solve_dual_quaternion),
        ),
        HandEyeSolver(
            "zhuang",
            AX_ZB,
            "AX = ZB, Zhuang et al. 1994 (quaternions, two stages)",
            _from_absolute_poses(solve_zhuang),
            zhuang_a0_check,
        ),
        HandEyeSolver(
            "refined",
            AX_ZB,
            "AX = ZB, Kronecker start + joint nonlinear least squares",
            _from_absolute_poses(solve_refined),
        ),
    )
}
HAND_EYE_METHODS = tuple(n for n, s in SOLVERS.items() if s.equation == AX_XB)
ROBOT_WORLD_METHODS = tuple(n for n, s in SOLVERS.items() if s.equation == AX_ZB)
ALL_METHODS = HAND_EYE_METHODS + ROBOT_WORLD_METHODS
#: The solver used when none is named (``cpc2urdf handeye``, the API): Li et al.'s Kronecker method.
DEFAULT_HANDEYE_METHOD = "kronecker"


@dataclass(frozen=True)
class Gate:
    """Options of the consistency gate (:func:`calibrate` with ``gate=``).

    Attributes:
        noise: The noise the poses' file states, or None (estimated from the data).
        labels: One name per pose (outliers are named by them).
        accept_inconsistent: Keep the result of inconsistent data, with the diagnosis in
            ``result.consistency`` and ``result.warnings``, instead of raising.
    """

    noise: PoseNoise | None = None
    labels: Sequence[str] | None = None
    accept_inconsistent: bool = False


_last_verdict: list[tuple[tuple[object, ...], ConsistencyReport]] = []


def _gate_verdict(
    H: Array, C: Array, noise: PoseNoise | None, labels: Sequence[str] | None
) -> ConsistencyReport:
    """The gate's verdict on these poses, computed once for the same poses, noise and labels.

    The verdict does not depend on the solver, and ``--method all`` asks it for the same poses
    seven times (1,000 poses: ~1.4 s each); the last one is kept (frozen, one entry).
    """
    key = (
        hashlib.sha256(H.tobytes() + C.tobytes()).hexdigest(),
        H.shape,
        noise,
        None if labels is None else tuple(labels),
    )
    if _last_verdict and _last_verdict[0][0] == key:
        return _last_verdict[0][1]
    report = check_consistency(H, C, noise=noise, labels=labels)
    _last_verdict[:] = [(key, report)]
    return report


def _run(
    T_base_hand: ArrayLike,
    T_camera_target: ArrayLike,
    method: str,
    methods: Sequence[str],
    kind: str,
    gate: Gate | bool,
) -> HandEyeResult:
    """Validate, diagnose (or gate) and solve with ``SOLVERS[method]``, which must be one of ``methods``."""
    if method not in methods:
        raise ValueError(f"unknown {kind}method {method!r}; known: {', '.join(methods)}")
    solver = SOLVERS[method]
    H = as_pose_stack(T_base_hand, "T_base_hand")
    C = as_pose_stack(T_camera_target, "T_camera_target")
    options = Gate() if gate is True else gate or None
    warnings = check_degenerate(H, C) if options is not None else diagnose(H, C)
    if solver.check is not None:
        warnings += solver.check(H)
    report: ConsistencyReport | None = None
    if options is not None:
        report = _gate_verdict(H, C, options.noise, options.labels)
        if not report.consistent and not options.accept_inconsistent:
            raise InconsistentPosesError(report)
        if not report.consistent:
            warnings.append(f"inconsistent data accepted: {report.summary()}")
        warnings += report.warnings
    X, Z = solver.solve(H, C)
    result = make_result(method, H, C, X, Z, warnings)
    return replace(result, consistency=report) if report is not None else result


def calibrate(
    T_base_hand: ArrayLike, T_camera_target: ArrayLike, method: str, *, gate: Gate | bool = False
) -> HandEyeResult:
    """Solve for ``X = T_hand_camera`` and ``Z = T_base_target`` with any solver of :data:`ALL_METHODS`.

    Args:
        T_base_hand: Hand poses in the robot base frame, shape (N, 4, 4) [m].
        T_camera_target: Target poses in the camera frame (solvePnP), shape (N, 4, 4) [m].
        method: One of :data:`ALL_METHODS`.
        gate: Run the consistency gate after the degenerate-data checks (``True``, or a
            :class:`Gate` with the stated noise, pose labels and whether to accept inconsistent
            data); ``False`` (default, the solver studies) keeps only the quick direction check.

    Returns:
        The solution with per-pose residuals and warnings (and, gated, ``consistency``).

    Raises:
        DegenerateDataError: See :func:`~cpc2urdf.identification.handeye.axxb.diagnose`, and hand
            rotations near 180 deg for ``zhuang``.
        InconsistentPosesError: Gated, the data contradict ``A X = Z B`` beyond chance (a
            ``DegenerateDataError``); the message names the most likely mistake.
        ValueError: Malformed poses or an unknown method.
    """
    return _run(T_base_hand, T_camera_target, method, ALL_METHODS, "", gate)


def calibrate_poses(
    poses: HandEyePoses, method: str, *, accept_inconsistent: bool = False
) -> HandEyeResult:
    """:func:`calibrate` of a pose file's poses through the consistency gate (the API and the CLI).

    The gate uses the file's ``noise`` (if stated) and names outliers by the records' labels.

    Raises:
        DegenerateDataError: As :func:`calibrate`.
        InconsistentPosesError: The poses contradict ``A X = Z B`` (unless ``accept_inconsistent``);
            the message names ``poses.source`` and the most likely mistake.
    """
    gate = Gate(noise=poses.noise, labels=poses.labels, accept_inconsistent=accept_inconsistent)
    try:
        return calibrate(poses.T_base_hand, poses.T_camera_target, method, gate=gate)
    except InconsistentPosesError as e:
        raise InconsistentPosesError(e.report, poses.source) from e


def calibrate_hand_eye(
    T_base_hand: ArrayLike, T_camera_target: ArrayLike, method: str = "tsai"
) -> HandEyeResult:
    """:func:`calibrate` restricted to the ``A X = X B`` solvers (:data:`HAND_EYE_METHODS`)."""
    return _run(T_base_hand, T_camera_target, method, HAND_EYE_METHODS, "AX=XB ", False)


def calibrate_robot_world(
    T_base_hand: ArrayLike, T_camera_target: ArrayLike, method: str = "kronecker"
) -> HandEyeResult:
    """:func:`calibrate` restricted to the ``A X = Z B`` solvers (:data:`ROBOT_WORLD_METHODS`)."""
    return _run(T_base_hand, T_camera_target, method, ROBOT_WORLD_METHODS, "AX=ZB ", False)


__all__ = [
    "DEFAULT_HANDEYE_METHOD",
    "ALL_METHODS",
    "AX_XB",
    "AX_ZB",
    "HAND_EYE_METHODS",
    "ROBOT_WORLD_METHODS",
    "SOLVERS",
    "Gate",
    "HandEyeSolver",
    "calibrate",
    "calibrate_hand_eye",
    "calibrate_poses",
    "calibrate_robot_world",
]
