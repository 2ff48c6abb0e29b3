"""Hand-eye input as setups record it: two pose streams on two clocks, paired by time.

The robot stream gives ``T_base_hand`` at times ``t_robot`` (robot clock), the camera stream
``T_camera_target`` at times ``t_camera`` (camera clock; rows without a measurement are NaN).
The clocks differ by a constant offset, KinHEC's convention::

    t_camera = t_robot + time_offset      # a frame stamped t was captured at robot time t - offset

so a positive offset means the camera's stamps run ahead. Pairing interpolates the robot stream
on SE(3) (slerp of the rotation, linear translation) at ``t_camera - time_offset``; camera frames
outside the robot stream's time span are dropped.

The offset, when not given, is estimated in two steps: the cross-correlation of the two streams'
angular speeds (the speed of a rigid body does not depend on the hand-eye transform; Furrer et al.
2017), then a bounded 1-D search for the offset that minimises the rotation residual of
``A X = Z B`` (``R_X``, ``R_Z`` fitted again at each trial offset). Its standard deviation comes
from the slopes and the curvature of that cost at the minimum (independent frames assumed).
Documented in ``docs/handeye.md`` ("Streams and CSV input").
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import minimize_scalar
from scipy.spatial.transform import Rotation, Slerp

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.handeye.axzb import rotation_rows
from cpc2urdf.transforms import Array, project_to_rotation, rotation_error, rotvec_from_matrix

SPEED_WINDOW = 0.1  # [s] angular speed from poses this far apart (noise vs time resolution)
GRID_RATE = 500.0  # [Hz] the cross-correlation's resampling grid
MAX_OFFSET = 0.5  # [s] the cross-correlation searches offsets up to this size
SEARCH_HALF_WIDTH = 0.05  # [s] the residual search around the cross-correlation's offset
SEARCH_SHIFTS = 2  # times the search window moves on when its minimum is at an edge
MAX_COST_FRAMES = 1000  # camera frames the residual cost uses at most (evenly spread)
KEYFRAME_ANGLE = np.radians(5.0)  # KinHEC's keyframes: 5 deg or 2 cm from the last one kept
KEYFRAME_DISTANCE = 0.02  # [m]
MAX_KEYFRAMES = 200


@dataclass(frozen=True)
class PoseStream:
    """Poses at increasing times, SI units; rows of NaN are frames without a measurement."""

    t: Array  # (N,) [s]
    T: Array  # (N, 4, 4)
    source: str = "<memory>"

    def valid(self) -> NDArray[np.bool_]:
        return np.isfinite(self.T).all(axis=(1, 2)) & np.isfinite(self.t)


@dataclass(frozen=True)
class StreamPairing:
    """How two streams became pose pairs (the command prints it).

    ``how`` is ``"given"`` (offset from the user), ``"estimated"`` (``sigma`` its standard
    deviation, ``coarse`` the cross-correlation's value) or ``"row-paired"`` (same time stamps:
    rows paired as they are, offset 0).
    """

    time_offset: float  # [s], t_camera = t_robot + time_offset
    how: str
    sigma: float | None = None  # [s]
    coarse: float | None = None  # [s]
    n_robot: int = 0
    n_camera: int = 0  # camera frames with a measurement
    n_paired: int = 0  # of those, inside the robot stream's time span
    n_keyframes: int = 0
    eye_to_hand: bool = False


def interpolate_poses(robot: PoseStream, t_query: Array) -> tuple[Array, NDArray[np.bool_]]:
    """Robot poses at ``t_query`` (robot clock): slerp + linear translation between samples.

    Returns:
        ``(T, inside)``: (M, 4, 4) poses (NaN outside the stream's span) and the (M,) mask.
    """
    ok = robot.valid()
    t, T = robot.t[ok], robot.T[ok]
    inside = (t_query >= t[0]) & (t_query <= t[-1])
    out = np.full((len(t_query), 4, 4), np.nan)
    tq = t_query[inside]
    out[inside, 3] = [0.0, 0.0, 0.0, 1.0]
    out[inside, :3, :3] = Slerp(t, Rotation.from_matrix(T[:, :3, :3]))(tq).as_matrix()
    for i in range(3):
        out[inside, i, 3] = np.interp(tq, t, T[:, i, 3])
    return out, inside


def angular_speed(t: Array, T: Array, window: float = SPEED_WINDOW) -> tuple[Array, Array]:
    """Rotation speed [rad/s] between poses ``window`` apart, stamped at the mid-points."""
    ok = np.isfinite(T).all(axis=(1, 2))
    t, T = t[ok], T[ok]
    i = np.arange(len(t))
    j = np.searchsorted(t, t + window)
    i, j = i[j < len(t)], j[j < len(t)]
    if len(i) < 3:
        return np.zeros(0), np.zeros(0)
    angle = rotation_error(T[i, :3, :3], T[j, :3, :3])
    return 0.5 * (t[i] + t[j]), angle / (t[j] - t[i])


def coarse_time_offset(
    robot: PoseStream, camera: PoseStream, max_offset: float = MAX_OFFSET
) -> float:
    """Offset maximising the normalised cross-correlation of the two angular speeds (Furrer et
    al. 2017, as KinHEC's ``estimate_time_offset``), to a fraction of the 2 ms grid.

    Raises:
        DegenerateDataError: The streams overlap too little or never change speed.
    """
    tr, wr = angular_speed(robot.t, robot.T)
    tc, wc = angular_speed(camera.t, camera.T)
    if len(tr) < 3 or len(tc) < 3:
        raise DegenerateDataError("streams too short to estimate the clock offset")
    dt = 1.0 / GRID_RATE
    grid = np.arange(min(tr[0], tc[0]) - max_offset, max(tr[-1], tc[-1]) + max_offset, dt)
    fr = np.interp(grid, tr, wr, left=np.nan, right=np.nan)
    fc = np.interp(grid, tc, wc, left=np.nan, right=np.nan)
    n, max_lag = len(grid), int(round(max_offset / dt))
    lags = np.arange(-max_lag, max_lag + 1)
    corr = np.full(len(lags), -np.inf)
    for k, lag in enumerate(
        lags
    ):  # the camera's speed is the robot's delayed: fc(t) = fr(t - offset)
        a, b = (fr[: n - lag], fc[lag:]) if lag >= 0 else (fr[-lag:], fc[: n + lag])
        m = np.isfinite(a) & np.isfinite(b)
        if m.sum() < 10:
            continue
        a, b = a[m] - a[m].mean(), b[m] - b[m].mean()
        denom = np.sqrt((a @ a) * (b @ b))
        if denom > 0:
            corr[k] = (a @ b) / denom
    if not np.isfinite(corr).any():
        raise DegenerateDataError(
            "cannot estimate the clock offset: the streams overlap too little or move at constant "
            "speed; give --time-offset"
        )
    k = int(np.argmax(corr))
    offset = lags[k] * dt
    if 0 < k < len(lags) - 1 and np.isfinite(corr[k - 1 : k + 2]).all():  # parabolic peak
        y0, y1, y2 = corr[k - 1 : k + 2]
        if abs(y0 - 2 * y1 + y2) > 1e-12:
            offset += 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2) * dt
    return float(offset)


def rotation_residuals(A: Array, C: Array) -> Array:
    """Rotation residuals (N, 3) [rad] of the least-squares fit of ``R_A R_X = R_Z R_B``,
    ``B = inv(C)``: the null vector of Li et al.'s eq. (17) rows (``[R_A ⊗ I, -I ⊗ R_Bᵀ]``, row-major
    vec, as :func:`~cpc2urdf.identification.handeye.axzb.solve_kronecker`), polar-projected."""
    RA, RB = A[:, :3, :3], np.swapaxes(C[:, :3, :3], -1, -2)
    M = rotation_rows(RA, RB)
    w = np.linalg.eigh(np.einsum("kri,krj->ij", M, M))[1][:, 0]
    w *= np.sign(np.linalg.det(w[:9].reshape(3, 3))) or 1.0
    RX, RZ = project_to_rotation(w[:9].reshape(3, 3)), project_to_rotation(w[9:].reshape(3, 3))
    E = np.swapaxes(RA @ RX, -1, -2) @ RZ @ RB
    return rotvec_from_matrix(E)


def refine_time_offset(
    robot: PoseStream, camera: PoseStream, start: float, half_width: float = SEARCH_HALF_WIDTH
) -> tuple[float, float]:
    """Offset minimising the rotation residual of ``A X = Z B`` within ``start ± half_width``,
    and its standard deviation.

    The cost is ``J(o) = Σ_k |e_k(o)|²`` over a fixed set of camera frames (those inside the robot
    span for every trial offset), ``e_k`` the :func:`rotation_residuals` with ``R_X``, ``R_Z``
    solved again at each ``o``. A 21-point grid finds the basin (moved on by its width up to
    ``SEARCH_SHIFTS`` times while the minimum is at an edge), Brent's method the minimum. The
    standard deviation is the sandwich ``sqrt(Σ_k j_k'²) / J''`` (``j_k = |e_k|²``, derivatives
    by central differences, the step shrunk to about two sigmas), assuming independent frames.
    Translations are left out: their residual mixes the camera's rotation noise times the
    camera-target distance with the position noise; on KinHEC's temporal track, adding them
    (each block whitened by its RMS) left the offsets 1.4x further off and their sigma 3-4x too
    small, and the position residual alone 2.3x and 90x.
    """
    t0, t1 = robot.t[robot.valid()][[0, -1]]
    reach = half_width * (1 + 2 * SEARCH_SHIFTS)
    use = camera.valid() & (camera.t - start - reach >= t0) & (camera.t - start + reach <= t1)
    idx = np.flatnonzero(use)
    if len(idx) < 3:
        raise DegenerateDataError("fewer than 3 camera frames overlap the robot stream")
    idx = idx[np.unique(np.linspace(0, len(idx) - 1, MAX_COST_FRAMES).round().astype(int))]
    tc, C = camera.t[idx], camera.T[idx]

    def frame_costs(offset: float) -> Array:
        e = rotation_residuals(interpolate_poses(robot, tc - offset)[0], C)
        return np.sum(e**2, axis=1)

    def cost(offset: float) -> float:
        return float(frame_costs(offset).sum())

    centre = start
    for _ in range(1 + SEARCH_SHIFTS):  # a minimum at the window's edge moves the window on
        grid = np.linspace(centre - half_width, centre + half_width, 21)
        k = int(np.argmin([cost(g) for g in grid]))
        if 0 < k < 20:
            break
        centre = grid[k]
    step = grid[1] - grid[0]
    bounds = (grid[max(k - 1, 0)], grid[min(k + 1, 20)])
    best = float(minimize_scalar(cost, bounds=bounds, method="bounded", options={"xatol": 1e-7}).x)
    if not 0 < k < 20:  # still at an edge: no minimum found, no uncertainty to give
        return best, float("inf")
    return best, _sandwich_sigma(frame_costs, best, step)


def _sandwich_sigma(frame_costs: Callable[[float], Array], at: float, h: float) -> float:
    """``sqrt(Σ j_k'²) / J''`` at the minimum; the step shrinks to about two sigmas."""
    j0 = frame_costs(at).sum()
    sigma = float("inf")
    for _ in range(3):
        jp, jm = frame_costs(at + h), frame_costs(at - h)
        curv = (jp.sum() - 2 * j0 + jm.sum()) / h**2
        if not curv > 0:
            return float("inf")
        sigma = float(np.sqrt(np.sum(((jp - jm) / (2 * h)) ** 2)) / curv)
        h = float(np.clip(2 * sigma, 1e-7, h))
    return sigma


def select_keyframes(
    T: Array,
    min_angle: float = KEYFRAME_ANGLE,
    min_distance: float = KEYFRAME_DISTANCE,
    max_keyframes: int = MAX_KEYFRAMES,
) -> Array:
    """Indices of keyframes (KinHEC's protocol): a pose is kept when it is ``min_angle`` [rad] or
    ``min_distance`` [m] from the last one kept; beyond ``max_keyframes``, evenly thinned."""
    keep, last = [0], T[0]
    for i in range(1, len(T)):
        angle = float(rotation_error(last[:3, :3], T[i, :3, :3]))
        if angle >= min_angle or np.linalg.norm(T[i, :3, 3] - last[:3, 3]) >= min_distance:
            keep.append(i)
            last = T[i]
    idx = np.array(keep)
    if len(idx) > max_keyframes:
        idx = idx[np.linspace(0, len(idx) - 1, max_keyframes).round().astype(int)]
    return idx


def row_paired(robot: PoseStream, camera: PoseStream) -> bool:
    """Both streams stamped with the same times, row by row (one clock, already paired)."""
    return len(robot.t) == len(camera.t) and bool(np.allclose(robot.t, camera.t, rtol=0, atol=1e-9))


def pair_streams(
    robot: PoseStream,
    camera: PoseStream,
    time_offset: float | None = None,
    *,
    keyframes: bool = True,
) -> tuple[Array, Array, Array, StreamPairing]:
    """Pose pairs from two streams: the robot at each measured camera frame's robot time.

    Args:
        robot: ``T_base_hand`` stream (robot clock).
        camera: ``T_camera_target`` stream (camera clock).
        time_offset: ``t_camera - t_robot`` [s] if known; otherwise 0 for row-paired streams,
            else estimated (:func:`coarse_time_offset`, then :func:`refine_time_offset`).
        keyframes: Keep only :func:`select_keyframes` of the paired hand poses.

    Returns:
        ``(t_camera, T_base_hand, T_camera_target, pairing)``, the pairs in camera time order.

    Raises:
        DegenerateDataError: Too few pairs, or an offset the streams cannot tell.
    """
    sigma = coarse = None
    if time_offset is not None:
        offset, how = float(time_offset), "given"
    elif row_paired(robot, camera):
        offset, how = 0.0, "row-paired"
    else:
        coarse = coarse_time_offset(robot, camera)
        offset, sigma = refine_time_offset(robot, camera, coarse)
        how = "estimated"
    measured = np.flatnonzero(camera.valid())
    if how == "row-paired":
        H, inside = robot.T[measured], robot.valid()[measured]
    else:
        H, inside = interpolate_poses(robot, camera.t[measured] - offset)
    frames = measured[inside]
    H = H[inside]
    if len(frames) < 3:
        raise DegenerateDataError(
            f"{len(frames)} camera frames fall inside the robot stream's time span "
            f"(offset {offset:+.4f} s); at least 3 are needed"
        )
    kept = select_keyframes(H) if keyframes else np.arange(len(H))
    pairing = StreamPairing(
        offset, how, sigma, coarse, int(robot.valid().sum()), len(measured), len(frames), len(kept)
    )
    return camera.t[frames[kept]], H[kept], camera.T[frames[kept]], pairing


__all__ = [
    "PoseStream",
    "StreamPairing",
    "angular_speed",
    "coarse_time_offset",
    "interpolate_poses",
    "pair_streams",
    "refine_time_offset",
    "row_paired",
    "select_keyframes",
]
