"""Simulated heads for testing and benchmarking gaze: a plausible calibrated IIS-head, and targets
known reachable (or not) built from the CPC model's own forward kinematics, independently of any
gaze solver.

The calibrated IIS-head is the nominal one with every joint's and frame's CPC constants perturbed
(seeded; 0.1 deg, 0.5 mm) and then the right camera trimmed in pitch (a rotation about its own x
axis) so that both optical axes meet at a point straight ahead at the home posture: the vertical
alignment every stereo head gets when mounted. Without the trim, a random perturbation often
leaves no fixable point in front of the cameras at all (the two eyes' planes cross behind them).

Reachable targets: sample neck and left-eye readings uniformly inside the limits (table at home);
on the nominal head sample the right eye too (the two optical axes are coplanar, so they meet at a
point: the target, kept if it lies in front of both cameras, 0.15-5 m away); on a calibrated head
the two eyes no longer sweep one plane, so for a sampled left eye only particular right-eye
readings make the axes meet: found by bisection on the signed distance between the two axes over
the right eye's range, the meeting point kept under the same conditions.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.model import CPCModel, CPCParams

Array = NDArray[np.float64]

CAMERAS = ("camera_left_optical", "camera_right_optical")
MIN_DISTANCE = 0.15  # [m]: targets closer than this to a camera are not generated
MAX_DISTANCE = 5.0  # [m]
PERTURB_ANGLE = math.radians(0.1)  # [rad]: std of the random rotation of each CPC transform
PERTURB_LENGTH = 0.5e-3  # [m]: std of the random translation of each CPC transform


def _rotvec_matrix(v: Array) -> Array:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(v).as_matrix()


def calibrated_iis_head(seed: int = 0, model: CPCModel | None = None) -> CPCModel:
    """A plausible calibrated IIS-head: the nominal with seeded small errors, right camera trimmed.

    Every joint's and frame's CPC transform is multiplied by a random rotation (std
    :data:`PERTURB_ANGLE` per axis) and shifted (std :data:`PERTURB_LENGTH`); then the right
    camera is rotated about its own x axis so that both optical axes meet straight ahead when
    the head is at home with symmetric vergence (see module docstring).

    Args:
        seed: Seed of the perturbation.
        model: The model to perturb; None: the shipped ``iis_head`` nominal.
    """
    from scipy.optimize import brentq

    from cpc2urdf.files.robot_ref import load_model

    nominal = model if model is not None else load_model("iis_head")
    rng = np.random.default_rng(seed)

    def perturb(p: CPCParams) -> CPCParams:
        T = p.matrix()
        T2 = T.copy()
        T2[:3, :3] = T[:3, :3] @ _rotvec_matrix(rng.normal(0.0, PERTURB_ANGLE, 3))
        T2[:3, 3] = T[:3, 3] + rng.normal(0.0, PERTURB_LENGTH, 3)
        return CPCParams.from_matrix(T2)

    joints = {n: perturb(p) for n, p in nominal.joints.items()}
    frames = {n: perturb(p) for n, p in nominal.frames.items()}
    m = nominal.with_params(joints=joints, frames=frames)
    s = m.structure
    q = 0.5 * (s.lower + s.upper)
    iL, iR = s.joint_index("vergence_left"), s.joint_index("vergence_right")
    q[iL] -= math.radians(5.0)  # converge symmetrically on a point ~0.7 m ahead
    q[iR] += math.radians(5.0)
    base = frames[CAMERAS[1]].matrix()

    def trimmed(phi: float) -> CPCModel:
        T = base.copy()
        T[:3, :3] = T[:3, :3] @ _rotvec_matrix(np.array([phi, 0.0, 0.0]))
        return m.with_params(frames={CAMERAS[1]: CPCParams.from_matrix(T)})

    phi = brentq(lambda a: float(axis_distance(trimmed(a), q)), -0.05, 0.05, xtol=1e-15)
    return trimmed(phi)


def _axes(model: CPCModel, Q: Array) -> tuple[Array, Array, Array, Array]:
    T = model.fk(Q, CAMERAS)
    L, R = T[CAMERAS[0]], T[CAMERAS[1]]
    return L[..., :3, 3], L[..., :3, 2], R[..., :3, 3], R[..., :3, 2]


def axis_distance(model: CPCModel, Q: Array) -> Array:
    """Signed distance between the two optical axes [m], shape (N,) for Q of shape (N, n)."""
    oL, zL, oR, zR = _axes(model, Q)
    n = np.cross(zL, zR)
    return np.einsum("...i,...i", oR - oL, n) / np.linalg.norm(n, axis=-1)


def axis_meeting(model: CPCModel, Q: Array) -> tuple[Array, Array, Array]:
    """Closest points of the two optical axes: (midpoint (N, 3), s_left (N,), s_right (N,)).

    ``s`` is the distance along each optical axis from the camera centre [m].
    """
    oL, zL, oR, zR = _axes(model, Q)
    w = oL - oR
    b = np.einsum("ij,ij->i", zL, zR)
    d, e = np.einsum("ij,ij->i", zL, w), np.einsum("ij,ij->i", zR, w)
    den = 1.0 - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (b * e - d) / den
        t = (e - b * d) / den
    mid = 0.5 * (oL + s[:, None] * zL + oR + t[:, None] * zR)
    return mid, s, t


def eyes_coplanar(model: CPCModel, tol: float = 1e-8) -> bool:
    """True if the two optical axes always meet (to ``tol`` [m]), as on the nominal IIS-head.

    Checked on 200 seeded configurations whose eyes differ by at least 10 deg.
    """
    s = model.structure
    rng = np.random.default_rng(12345)
    Q = s.lower + (s.upper - s.lower) * rng.random((200, s.n_joints))
    iL, iR = s.joint_index("vergence_left"), s.joint_index("vergence_right")
    Q = Q[np.abs(Q[:, iL] - Q[:, iR]) > math.radians(10.0)]
    return bool(np.max(np.abs(axis_distance(model, Q))) < tol)


def reachable_targets(
    model: CPCModel, n: int, seed: int = 0, *, q_table: Array | None = None, max_rounds: int = 200
) -> tuple[Array, Array]:
    """``n`` targets that ``model`` fixates exactly, and the readings that do it.

    See the module docstring for the construction. Only the CPC model's forward kinematics is
    used (not Pinocchio, not the solver).

    Args:
        model: Head model with joints table_x, table_y, pan, tilt, vergence_left/right.
        n: Number of targets.
        seed: Seed of the sampled readings.
        q_table: Table readings [m], shape (2,); None: the middle of the limits.
        max_rounds: Rounds of sampled readings before giving up.

    Returns:
        ``(P, Q)``: targets (world) [m], shape (n, 3); readings, shape (n, 6).

    Raises:
        DegenerateDataError: Fewer than ``n`` targets after ``max_rounds`` rounds: this head's
            two optical axes (almost) never meet in front of the cameras within its limits.
    """
    s = model.structure
    rng = np.random.default_rng(seed)
    lo, hi = s.lower, s.upper
    iR = s.joint_index("vergence_right")
    home = 0.5 * (lo + hi)
    table = [s.joint_index("table_x"), s.joint_index("table_y")]
    out_P: list[Array] = []
    out_Q: list[Array] = []
    grid = np.linspace(lo[iR], hi[iR], 19)
    coplanar = eyes_coplanar(model)
    for _round in range(max_rounds):
        if sum(len(p) for p in out_P) >= n:
            break
        m = max(2 * n, 64)
        Q = lo + (hi - lo) * rng.random((m, s.n_joints))
        Q[:, table] = home[table] if q_table is None else q_table
        # signed axis distance over the right eye's range, all samples at once
        if not coplanar:
            G = np.repeat(Q[:, None, :], grid.size, axis=1)
            G[:, :, iR] = grid
            f = axis_distance(model, G.reshape(-1, s.n_joints)).reshape(m, grid.size)
        if coplanar:  # every right-eye reading meets the left axis
            Qs = Q
        else:
            sign = np.sign(f)
            change = (sign[:, :-1] * sign[:, 1:] < 0) & (np.abs(f[:, :-1] - f[:, 1:]) < 0.05)
            has = change.any(axis=1)
            Q, f, change = Q[has], f[has], change[has]
            k = np.argmax(change, axis=1)
            a, b = grid[k], grid[k + 1]
            fa = f[np.arange(len(Q)), k]
            for _ in range(50):  # vectorised bisection: grid step / 2^50 < 1e-16 rad
                c = 0.5 * (a + b)
                Qc = Q.copy()
                Qc[:, iR] = c
                fc = axis_distance(model, Qc)
                left = np.sign(fc) == np.sign(fa)
                a = np.where(left, c, a)
                fa = np.where(left, fc, fa)
                b = np.where(left, b, c)
            Qs = Q.copy()
            Qs[:, iR] = 0.5 * (a + b)
        mid, sl, sr = axis_meeting(model, Qs)
        ok = (sl > MIN_DISTANCE) & (sr > MIN_DISTANCE) & (sl < MAX_DISTANCE) & (sr < MAX_DISTANCE)
        ok &= np.abs(axis_distance(model, Qs)) < (1e-9 if coplanar else 1e-12)
        out_P.append(mid[ok])
        out_Q.append(Qs[ok])
    found = sum(len(p) for p in out_P)
    if found < n:
        raise DegenerateDataError(
            f"{model.structure.name}: only {found} of {n} targets found where both optical axes meet "
            f"{MIN_DISTANCE:g}-{MAX_DISTANCE:g} m in front of the cameras, in {max_rounds} rounds of "
            f"{max(2 * n, 64)} sampled readings within the limits (table fixed)"
        )
    return np.concatenate(out_P)[:n], np.concatenate(out_Q)[:n]


def unreachable_targets(model: CPCModel, n: int, seed: int = 0) -> Array:
    """``n`` targets no configuration can fixate (world) [m], shape (n, 3), in two families.

    - Behind the head: pan turns through [0, 180] deg about home (90 deg, facing forward), the
      eyes add at most 45 deg either way, so directions within 17 deg of straight back (here
      lateral slope <= 0.3), 0.5-3 m away, are out of reach.
    - Beyond the tilt range: 10-20 m up or down the pan axis (elevation ~90 deg; tilt spans
      60 deg).

    (Targets merely closer than the baseline are *not* unreachable on the IIS-head: the cameras
    orbit the vergence axis and can converge on points between them once the head moves; see
    :func:`too_close_targets` for the head-still case.)
    """
    s = model.structure
    rng = np.random.default_rng(seed)
    home = 0.5 * (s.lower + s.upper)
    T = model.fk(home)
    p_axes, axes_dir = model.joint_axes_world(home)
    ip = s.joint_index("pan")
    pan_axis, pan_point = axes_dir[0, ip], p_axes[0, ip]
    fwd = (T[CAMERAS[0]][:3, 2] + T[CAMERAS[1]][:3, 2]) / 2.0
    fwd -= (fwd @ pan_axis) * pan_axis
    fwd /= np.linalg.norm(fwd)
    side = np.cross(pan_axis, fwd)
    k = n // 2
    d = rng.uniform(0.5, 3.0, k)
    lat = rng.uniform(-0.3, 0.3, k)
    up = rng.uniform(-0.2, 0.2, k)
    behind = pan_point - d[:, None] * fwd + (lat * d)[:, None] * side + up[:, None] * pan_axis
    m = n - k
    sign = np.where(rng.random(m) < 0.5, -1.0, 1.0)
    far = pan_point + (sign * rng.uniform(10.0, 20.0, m))[:, None] * pan_axis
    return np.concatenate([behind, far])


def too_close_targets(
    model: CPCModel, q: Array, n: int, seed: int = 0, radius: float = 0.04
) -> Array:
    """Targets the eyes alone cannot fixate at readings ``q``: inside the cameras' orbit.

    Each camera orbits its vergence axis (radius ~60 mm on the IIS-head) with its optical axis
    tangent to the orbit, so with the head still no optical axis passes within the orbit. The
    targets lie in the left eye's plane (through its camera centre, normal to its vergence
    axis) within ``radius`` [m] of that axis. Shape (n, 3), world [m].
    """
    s = model.structure
    rng = np.random.default_rng(seed)
    iL = s.joint_index("vergence_left")
    p_axes, axes_dir = model.joint_axes_world(q)
    a, u = p_axes[0, iL], axes_dir[0, iL]
    o = model.fk(q)[CAMERAS[0]][:3, 3]
    centre = a + ((o - a) @ u) * u
    e1 = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    r = radius * np.sqrt(rng.random(n))
    phi = rng.uniform(0.0, 2.0 * math.pi, n)
    return centre + r[:, None] * (np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2)


__all__ = [
    "CAMERAS",
    "MAX_DISTANCE",
    "MIN_DISTANCE",
    "PERTURB_ANGLE",
    "PERTURB_LENGTH",
    "axis_distance",
    "axis_meeting",
    "calibrated_iis_head",
    "eyes_coplanar",
    "reachable_targets",
    "too_close_targets",
    "unreachable_targets",
]
