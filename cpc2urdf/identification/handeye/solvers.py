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

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.handeye.axxb import (
    MIN_POSES,
    HandEyeResult,
    as_pose_stack,
    check_degenerate,
    diagnose,
    make_result,
    relative_motions,
    residuals,
    rotation_degeneracy,
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
    ESTIMATED,
    ConsistencyReport,
    InconsistentPosesError,
)
from cpc2urdf.identification.handeye.gate.handeye_gate import (
    IMPLAUSIBLE_ANGLE,
    IMPLAUSIBLE_RESIDUAL,
    check_consistency,
)
from cpc2urdf.identification.handeye.likelihood import (
    OUTLIER_PROBABILITY,
    LikelihoodFit,
    solve_likelihood,
    solve_xz,
)
from cpc2urdf.identification.handeye.pose_file import HandEyePoses
from cpc2urdf.identification.handeye.pose_noise import PoseNoise
from cpc2urdf.transforms import Array, inverse, project_to_rotation, rotation_error

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
            "ml",
            AX_ZB,
            "AX = ZB, joint maximum likelihood: noise estimated, outliers dropped",
            solve_xz,
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
#: The solver used when none is named (``cpc2urdf handeye``, the API): the joint maximum likelihood.
DEFAULT_HANDEYE_METHOD = "ml"


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


_last_verdict: list[
    tuple[tuple[object, ...], LikelihoodFit, ConsistencyReport, NDArray[np.bool_]]
] = []
#: Verdicts that isolated outliers can cause: judged again without the poses the fit drops.
_OUTLIER_CODES = ("outliers", "implausible", "noise_exceeded")


def _gate_verdict(
    H: Array, C: Array, noise: PoseNoise | None, labels: Sequence[str] | None, unknown_scale: bool
) -> tuple[LikelihoodFit, ConsistencyReport, NDArray[np.bool_]]:
    """The maximum-likelihood fit (outliers found, the scale estimated if unknown), the gate's
    verdict and the poses every solver gets, computed once for the same poses, noise and labels.

    The gate judges all poses: a mistake it names (inverted poses, a unit, pairs off by one) is
    refused. When what it finds is what isolated outliers cause, it judges again without the
    poses the fit drops, and the solvers get only those kept. Nothing here depends on the solver,
    and ``--method all`` asks seven times (1,000 poses: ~1.4 s each); the last answer is kept.
    """
    key = (
        hashlib.sha256(H.tobytes() + C.tobytes()).hexdigest(),
        H.shape,
        noise,
        None if labels is None else tuple(labels),
        unknown_scale,
    )
    if _last_verdict and _last_verdict[0][0] == key:
        return _last_verdict[0][1:]
    fit = solve_likelihood(H, C, estimate_scale=unknown_scale)
    Cm = _metric(C, fit.scale)
    names = [f"pose {k}" for k in range(len(H))] if labels is None else [str(x) for x in labels]
    if len(set(names)) < len(names):  # the gate names outliers by label: make them unique
        names = [f"{x} (pose {k})" for k, x in enumerate(names)]
    report = check_consistency(H, Cm, noise=noise, labels=names)
    keep = np.ones(len(H), dtype=bool)
    if not report.consistent and report.code in _OUTLIER_CODES:
        keep = fit.inliers & ~np.isin(names, report.outliers)
        if not np.array_equal(keep, fit.inliers):  # the gate named more: fit again without them
            inner = solve_likelihood(H[keep], C[keep], estimate_scale=unknown_scale)
            keep[keep] = inner.inliers
            fit = replace(inner, inliers=keep)
            Cm = _metric(C, fit.scale)
        if not keep.all():
            kept = [str(x) for x, k in zip(names, keep, strict=True) if k]
            report = check_consistency(H[keep], Cm[keep], noise=noise, labels=kept)
        if report.code == "implausible":  # the gate's quick fit, or the poses, too far off?
            report = _level_of_the_fit(report, H[keep], Cm[keep], fit)
    elif not report.consistent and 2 * fit.inliers.sum() >= len(H) and not fit.inliers.all():
        # a mistake named on all poses, but the fit keeps a majority: do the kept poses agree?
        kept = [str(x) for x, k in zip(names, fit.inliers, strict=True) if k]
        verdict = check_consistency(H[fit.inliers], Cm[fit.inliers], noise=noise, labels=kept)
        if verdict.consistent:
            mistake = f"on all poses the gate read {report.cause}; the poses kept agree"
            keep, report = fit.inliers, replace(verdict, warnings=(*verdict.warnings, mistake))
    _last_verdict[:] = [(key, fit, report, keep)]
    return fit, report, keep


def _level_of_the_fit(
    report: ConsistencyReport, H: Array, C: Array, fit: LikelihoodFit
) -> ConsistencyReport:
    """An "implausible residuals" verdict judged again on the maximum-likelihood fit: the gate's
    quick fit can be far off where the noise is heavy and anisotropic. Consistent, with a warning,
    when that fit's residuals are below the gate's limits."""
    dt, dr = residuals(H, C, fit.X, fit.Z)
    rms_t, rms_r = float(np.sqrt(np.mean(dt**2))), float(np.sqrt(np.mean(dr**2)))
    distance = float(np.median(np.linalg.norm(C[:, :3, 3], axis=1)))
    if rms_t > IMPLAUSIBLE_RESIDUAL * distance or rms_r > IMPLAUSIBLE_ANGLE:
        return report
    return ConsistencyReport(
        consistent=True,
        noise=ESTIMATED,
        rms_translation=rms_t,
        rms_rotation=rms_r,
        warnings=(
            f"large residuals: {rms_t * 1e3:.3g} mm / {np.degrees(rms_r):.3g} deg RMS in the "
            f"maximum-likelihood fit at a camera-target distance of {distance * 1e3:.3g} mm "
            f"(a quick fit left {report.rms_translation * 1e3:.3g} mm / "
            f"{np.degrees(report.rms_rotation):.3g} deg)",
        ),
    )


#: Closed forms the default is compared with, and how far (times their spread plus its own
#: standard deviation) it may be from what they agree on before it says so.
CLOSED_FORMS = ("tsai", "park_martin", "kronecker", "dual_quaternion")
DISAGREEMENT = 5.0


def _against_closed_forms(H: Array, C: Array, fit: LikelihoodFit) -> list[str]:
    """A warning when the closed forms agree with each other but not with ``fit`` beyond their
    noise: which, by how much, and what differs (empty otherwise)."""
    Xs = {}
    for name in CLOSED_FORMS:
        try:
            Xs[name] = SOLVERS[name].solve(H, C)[0]
        except (DegenerateDataError, np.linalg.LinAlgError):
            continue
    if len(Xs) < 3:
        return []
    t = np.array([X[:3, 3] for X in Xs.values()])
    R = np.array([X[:3, :3] for X in Xs.values()])
    t0, R0 = np.median(t, axis=0), project_to_rotation(R.mean(axis=0))
    spread_t = float(np.median(np.linalg.norm(t - t0, axis=1)))
    spread_r = float(np.median(rotation_error(R0[None], R)))
    sd = np.sqrt(np.maximum(np.diag(fit.covariance)[:6], 0.0))
    off_t = float(np.linalg.norm(fit.X[:3, 3] - t0))
    off_r = float(rotation_error(R0, fit.X[:3, :3]))
    far_t = off_t > DISAGREEMENT * (spread_t + float(np.linalg.norm(sd[3:6]))) and off_t > 1e-6
    far_r = off_r > DISAGREEMENT * (spread_r + float(np.linalg.norm(sd[0:3]))) and off_r > 1e-6
    if not (far_t or far_r):
        return []
    return [
        f"ml is {off_t * 1e3:.3g} mm / {np.degrees(off_r):.3g} deg from what {', '.join(Xs)} agree "
        f"on (within {spread_t * 1e3:.3g} mm / {np.degrees(spread_r):.3g} deg of each other; ml's "
        f"own standard deviation {np.linalg.norm(sd[3:6]) * 1e3:.3g} mm / "
        f"{np.degrees(np.linalg.norm(sd[0:3])):.3g} deg): it weights the poses by the noise it "
        f"estimated ({_noise_words(fit.noise)}), they weight all alike; if that noise is not "
        "your setup's, compare with --method all"
    ]


def _noise_words(sd: Array) -> str:
    """The estimated noise levels of :data:`likelihood.NOISE_GROUPS`, in words."""
    return (
        f"hand {np.degrees(sd[0]):.2g} deg / {sd[1] * 1e3:.2g} mm, target "
        f"{np.degrees(sd[2:5].max()):.2g} deg / {sd[5:8].max() * 1e3:.2g} mm at most per axis"
    )


def _partly_determined(H: Array, C: Array) -> str:
    """Why the hand rotations leave part of X and Z undetermined ("" if they do not, or if the
    data have other problems, which :func:`check_degenerate` then refuses)."""
    if len(H) != len(C) or len(H) < MIN_POSES:
        return ""
    return rotation_degeneracy(H)


def _metric(C: Array, scale: float) -> Array:
    """Target poses with their translations divided by ``scale``."""
    if scale == 1.0:
        return C
    out = C.copy()
    out[:, :3, 3] /= scale
    return out


def _run(
    T_base_hand: ArrayLike,
    T_camera_target: ArrayLike,
    method: str,
    methods: Sequence[str],
    kind: str,
    gate: Gate | bool,
    unknown_scale: bool = False,
) -> HandEyeResult:
    """Validate, diagnose (or gate) and solve with ``SOLVERS[method]``, which must be one of
    ``methods``. Gated, every solver gets the poses the maximum-likelihood fit keeps."""
    if method not in methods:
        raise ValueError(f"unknown {kind}method {method!r}; known: {', '.join(methods)}")
    if unknown_scale and method != "ml":
        raise DegenerateDataError(
            f"{method} needs metric target poses; only ml estimates an unknown scale"
        )
    solver = SOLVERS[method]
    H = as_pose_stack(T_base_hand, "T_base_hand")
    C = as_pose_stack(T_camera_target, "T_camera_target")
    options = Gate() if gate is True else gate or None
    partial = _partly_determined(H, C) if method == "ml" else ""
    labels = options.labels if options is not None else None
    if partial:  # ml gives the determined part and names the rest
        warnings = [
            f"partly determined: {partial}",
            "consistency gate not run: it needs poses that determine X and Z",
        ]
        options = None
    else:
        warnings = check_degenerate(H, C) if options is not None else diagnose(H, C)
    if solver.check is not None:
        warnings += solver.check(H)
    report: ConsistencyReport | None = None
    if options is not None:
        fit, report, keep = _gate_verdict(H, C, options.noise, options.labels, unknown_scale)
        if not report.consistent and not options.accept_inconsistent:
            raise InconsistentPosesError(report)
        if not report.consistent:
            warnings.append(f"inconsistent data accepted: {report.summary()}")
        warnings += report.warnings
    else:
        keep = np.ones(len(H), dtype=bool)
        if method == "ml":
            fit = solve_likelihood(H, C, estimate_scale=unknown_scale)
    if unknown_scale:
        C = _metric(C, fit.scale)
        warnings.append(f"target translations were {fit.scale:.6g} times the metric ones")
    keep = fit.inliers if method == "ml" else keep
    warnings += fit.undetermined_words() if method == "ml" else []
    if not keep.all():
        warnings.append(_dropped(keep, labels))
    X, Z = (fit.X, fit.Z) if method == "ml" else solver.solve(H[keep], C[keep])
    if method == "ml" and not partial:
        warnings += _against_closed_forms(H[keep], C[keep], fit)
    result = make_result(method, H, C, X, Z, warnings)
    return replace(result, consistency=report) if report is not None else result


def _dropped(keep: NDArray[np.bool_], labels: Sequence[str] | None) -> str:
    """The warning naming the poses the maximum-likelihood fit dropped as outliers."""
    out = [int(k) for k in np.flatnonzero(~keep)]
    names = [str(labels[k]) if labels is not None else f"pose {k}" for k in out]
    shown = ", ".join(names[:10]) + (f" and {len(names) - 10} more" if len(names) > 10 else "")
    return (
        f"{len(out)} of {len(keep)} poses dropped as outliers (residual beyond the "
        f"{OUTLIER_PROBABILITY:.1%} point of the fitted noise): {shown}"
    )


def calibrate(
    T_base_hand: ArrayLike,
    T_camera_target: ArrayLike,
    method: str,
    *,
    gate: Gate | bool = False,
    unknown_scale: bool = False,
) -> HandEyeResult:
    """Solve for ``X = T_hand_camera`` and ``Z = T_base_target`` with any solver of :data:`ALL_METHODS`.

    Args:
        T_base_hand: Hand poses in the robot base frame, shape (N, 4, 4) [m].
        T_camera_target: Target poses in the camera frame (solvePnP), shape (N, 4, 4) [m].
        method: One of :data:`ALL_METHODS`.
        gate: Run the consistency gate after the degenerate-data checks (``True``, or a
            :class:`Gate` with the stated noise, pose labels and whether to accept inconsistent
            data); ``False`` (default, the solver studies) keeps only the quick direction check.
        unknown_scale: The target translations are known up to one factor (a monocular
            visual-odometry trajectory): ``ml`` estimates it; the residuals are then metric.

    Returns:
        The solution with per-pose residuals and warnings (and, gated, ``consistency``).

    Raises:
        DegenerateDataError: See :func:`~cpc2urdf.identification.handeye.axxb.diagnose`, and hand
            rotations near 180 deg for ``zhuang``.
        InconsistentPosesError: Gated, the data contradict ``A X = Z B`` beyond chance (a
            ``DegenerateDataError``); the message names the most likely mistake.
        ValueError: Malformed poses or an unknown method.
    """
    return _run(T_base_hand, T_camera_target, method, ALL_METHODS, "", gate, unknown_scale)


def calibrate_poses(
    poses: HandEyePoses,
    method: str,
    *,
    accept_inconsistent: bool = False,
    unknown_scale: bool = False,
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
        return calibrate(
            poses.T_base_hand, poses.T_camera_target, method, gate=gate, unknown_scale=unknown_scale
        )
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
