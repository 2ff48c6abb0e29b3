"""The fixation task (priority 1 of the gaze solver): residual, Jacobian and null space.

A target ``p_world`` [m] is *fixated* when the optical (z) axis of each camera frame passes
through it, in front of the camera. Per eye the residual is ``u - e_z``, with ``u`` the unit
target direction in the camera frame: zero only when the camera looks *at*, not away from, the
target; its norm is ``2 sin(err/2)``. Its Jacobian comes from Pinocchio's LOCAL frame
Jacobians: ``dp_cam = -v - w x p_cam``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze.head import GazeHead, Index

NULL_EIGENVALUE = 1e-14  # [-]: eigenvalues of J1^T J1 below this span the fixation null space
MIN_TARGET_DISTANCE = 1e-9  # [m]: a target this close to a camera centre cannot be pointed at
SCALED_DISTANCE = 1e150  # [m]: beyond this from a camera, p_cam is computed scaled (no overflow)


def target_point(p_world: ArrayLike) -> Array:
    """A gaze target as a finite point of shape (3,) [m], or :class:`ConfigurationError` saying
    what is wrong (the solver and the view check targets the same way). Always a new
    C-contiguous array: the solver keeps it in its answer and the kernels take it as it is."""
    try:
        p = np.array(p_world, dtype=float)
    except (TypeError, ValueError) as e:
        raise ConfigurationError(f"target must be three numbers x y z [m], got {p_world!r}") from e
    if p.shape != (3,):
        raise ConfigurationError(f"target must be three numbers x y z [m], got shape {p.shape}")
    x, y, z = p.tolist()
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        raise ConfigurationError(f"target must be finite, got {p.tolist()}")
    return p


@dataclass(slots=True)
class FixationState:
    """Per-configuration quantities of both eyes (computed by :func:`evaluate_fixation`).

    The 3-vectors are plain float lists: the solver's hot path does its 3-vector algebra in
    Python floats, which is several times cheaper than numpy calls on arrays this small. The
    Jacobian is computed when first asked for: the last configuration of a solve (and every
    backtracking trial) only needs the residual.
    """

    head: GazeHead
    q: Array  # (n,) the readings [rad]/[m]
    r: Array  # (6,) fixation residual, [u_L - e_z, u_R - e_z]
    rr: float  # |r|^2
    origins: list[list[float]]  # 2 x 3: camera centres (world) [m]
    axes: list[list[float]]  # 2 x 3: optical axes (world)
    p_cam: list[tuple[float, float, float]]  # 2 x 3: target in each camera frame [m]
    u: list[tuple[float, float, float, float]]  # 2 x 4: unit target direction (camera) and 1 / |p_cam|
    jacobian: Array | None = None
    Jo: list[Array] | None = None  # use-table: the (3, n) world Jacobians of the camera centres

    @property
    def J(self) -> Array:
        """(6, n) Jacobian of ``r`` by the readings."""
        if self.jacobian is None:
            self.jacobian = fixation_jacobian(self.head, self)
        return self.jacobian


def _direction_outside(
    dx: float, dy: float, dz: float, R: tuple[float, float, float, float, float, float, float, float, float]
) -> tuple[float, float, float, float, float, float, float]:
    """The target in the camera frame, its unit direction and ``1 / |p_cam|`` where the direct
    formula fails: ``(x, y, z, ux, uy, uz, inv)``.

    ``(dx, dy, dz)`` is ``p - o`` (world) [m] and ``R`` the camera rotation, row by row.
    Within :data:`MIN_TARGET_DISTANCE` of the camera centre the direction is undefined: ``u = 0``
    (residual ``(0, 0, -1)``, counted as missed by pi) and ``inv = 0``, so this eye's Jacobian
    block is zero rather than infinite: the eye cannot point at a target on its own centre, and
    the step is taken by the other eye (or the motion that carries this camera off the target).
    Beyond :data:`SCALED_DISTANCE` the rotation runs on ``p - o`` scaled by a power of two (exact),
    so squares cannot overflow; ``inv`` (below 1e-150) is taken as 0, and a coordinate beyond the
    largest float is inf.
    """
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R
    m = max(abs(dx), abs(dy), abs(dz))
    if m < 1.0:  # within MIN_TARGET_DISTANCE of the centre: exact coordinates, no direction
        x = r00 * dx + r10 * dy + r20 * dz
        y = r01 * dx + r11 * dy + r21 * dz
        z = r02 * dx + r12 * dy + r22 * dz
        return x, y, z, 0.0, 0.0, 0.0, 0.0
    k = math.frexp(m)[1]  # m = f 2^k with 0.5 <= f < 1, k <= 1024
    s = math.ldexp(1.0, -k)
    sx, sy, sz = dx * s, dy * s, dz * s  # exact: scaled by a power of two, in [-1, 1]
    xs = r00 * sx + r10 * sy + r20 * sz
    ys = r01 * sx + r11 * sy + r21 * sz
    zs = r02 * sx + r12 * sy + r22 * sz
    inv_s = 1.0 / math.sqrt(xs * xs + ys * ys + zs * zs)  # |(xs, ys, zs)| = |s (p - o)| in [0.5, 1.8]
    half = math.ldexp(1.0, k - 1)  # 2^k itself overflows for k = 1024; Python floats go to inf silently
    return xs * half * 2.0, ys * half * 2.0, zs * half * 2.0, xs * inv_s, ys * inv_s, zs * inv_s, 0.0


def evaluate_fixation(head: GazeHead, q: Array, p: Array, jacobian: bool = True) -> FixationState:
    """Residual state at readings ``q`` (shape (n,)) for target ``p`` (world) [m], shape (3,);
    its Jacobian now (``jacobian``) or when first used."""
    head.pin.framesForwardKinematics(head.model, head.data, q)
    px, py, pz = p.tolist()
    oMf = head.data.oMf
    res: list[float] = []
    origins, axes, p_cam, us = [], [], [], []
    rr = 0.0
    for fid in head.frame_ids:
        (r00, r01, r02, ox), (r10, r11, r12, oy), (r20, r21, r22, oz), _ = oMf[fid].homogeneous.tolist()
        # the target in the camera frame: R^T (p - o)
        dx, dy, dz = px - ox, py - oy, pz - oz
        x = r00 * dx + r10 * dy + r20 * dz
        y = r01 * dx + r11 * dy + r21 * dz
        z = r02 * dx + r12 * dy + r22 * dz
        nrm = math.sqrt(x * x + y * y + z * z)
        if MIN_TARGET_DISTANCE <= nrm <= SCALED_DISTANCE:
            inv = 1.0 / nrm
            ux, uy, uz = x * inv, y * inv, z * inv
        else:  # rare: on a camera centre, or astronomically far (NaN-safe test)
            x, y, z, ux, uy, uz, inv = _direction_outside(dx, dy, dz, (r00, r01, r02, r10, r11, r12, r20, r21, r22))
        res += (ux, uy, uz - 1.0)
        rr += ux * ux + uy * uy + (uz - 1.0) * (uz - 1.0)
        origins.append([ox, oy, oz])
        axes.append([r02, r12, r22])
        p_cam.append((x, y, z))
        us.append((ux, uy, uz, inv))
    st = FixationState(head, q.copy(), np.array(res), rr, origins, axes, p_cam, us)
    if jacobian:
        st.J  # noqa: B018 (computed now, while q is the caller's)
    return st


def pointing_errors(st: FixationState) -> list[float]:
    """Angle [rad] between each camera's optical axis and the direction to the target, (left,
    right); pi for a target within :data:`MIN_TARGET_DISTANCE` of that camera's centre (no
    direction to point along)."""
    # from p_cam while it is finite (0 * (x + y + z) is 0.0), else from the direction (a
    # coordinate beyond the largest float)
    return [
        math.pi if not (ux or uy or uz)
        else math.atan2(math.hypot(x, y), z) if 0.0 * (x + y + z) == 0.0
        else math.atan2(math.hypot(ux, uy), uz)
        for (x, y, z), (ux, uy, uz, _) in zip(st.p_cam, st.u, strict=True)
    ]


def fixation_jacobian(head: GazeHead, st: FixationState) -> Array:
    """(6, n) Jacobian of the fixation residual at ``st.q``, from Pinocchio's LOCAL frame Jacobians."""
    pin = head.pin
    model, data = head.model, head.data
    pin.computeJointJacobians(model, data, st.q)
    pin.updateFramePlacements(model, data)
    blocks = []
    for fid, (ux, uy, uz, inv) in zip(head.frame_ids, st.u, strict=True):
        # d p_cam = -v - w x p_cam = [-I | [p_cam]x] (v; w), the LOCAL twist of the camera;
        # d u = P d p_cam with P = (I - u u^T) / |p_cam|: one (3, 6) matrix times the frame
        # Jacobian, [-P | P [p_cam]x], where P [p_cam]x = [u]x (as u^T [u]x = 0).
        wx, wy, wz = ux * inv, uy * inv, uz * inv
        M = [
            [ux * wx - inv, ux * wy, ux * wz, 0.0, -uz, uy],
            [uy * wx, uy * wy - inv, uy * wz, uz, 0.0, -ux],
            [uz * wx, uz * wy, uz * wz - inv, -uy, ux, 0.0],
        ]
        blocks.append(np.array(M) @ pin.getFrameJacobian(model, data, fid, pin.LOCAL))
    return np.concatenate(blocks)


def closest_point(origins: Sequence[Sequence[float]], axes: Sequence[Sequence[float]]) -> Array | None:
    """Midpoint of the closest points of two lines ``origins[k] + t axes[k]``; None if parallel.

    ``origins`` and ``axes`` are 2 x 3 (float lists or an array's rows).
    """
    d0, d1 = axes
    o0, o1 = origins
    w = [o0[i] - o1[i] for i in range(3)]
    a = d0[0] * d0[0] + d0[1] * d0[1] + d0[2] * d0[2]
    b = d0[0] * d1[0] + d0[1] * d1[1] + d0[2] * d1[2]
    c = d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2]
    den = a * c - b * b
    if den < 1e-14:
        return None
    dd = d0[0] * w[0] + d0[1] * w[1] + d0[2] * w[2]
    e = d1[0] * w[0] + d1[1] * w[1] + d1[2] * w[2]
    s = (b * e - c * dd) / den
    t = (a * e - b * dd) / den
    return np.array([0.5 * (o0[i] + s * d0[i] + o1[i] + t * d1[i]) for i in range(3)])


def fixation_redundancy(head: GazeHead, free: Index) -> tuple[bool, float]:
    """Whether fixation by the joints ``free`` leaves an exact null space (e.g. the nominal
    IIS-head with neck and eyes), and the sign of the eye offset that converges the eyes.

    Tested at a converging home posture on the closest point of the two optical axes.
    A calibrated head whose eyes do not sweep one plane has none: the redundancy policy
    then has no freedom, and the solver goes straight to solving fixation alone.

    Returns:
        ``(redundant, converge_sign)``: ``converge_sign`` is +1 when turning the first left eye
        joint by ``-delta`` and the first right one by ``version_sign * delta`` (``delta > 0``)
        converges the eyes, else -1 (+1 if neither direction converges them).
    """
    q = head.home.copy()
    e0, e1 = head.e0, head.e1
    converge_sign = 1.0
    for delta in (0.1, -0.1):
        q[e0] = np.clip(head.home[e0] - delta, head.lower[e0], head.upper[e0])
        q[e1] = np.clip(head.home[e1] + head.version_sign * delta, head.lower[e1], head.upper[e1])
        head.pin.framesForwardKinematics(head.model, head.data, q)
        o = np.array([head.data.oMf[fid].translation for fid in head.frame_ids])
        z = np.array([head.data.oMf[fid].rotation[:, 2] for fid in head.frame_ids])
        p = closest_point(o.tolist(), z.tolist())
        if p is None:
            continue
        st = evaluate_fixation(head, q, p)
        J = st.J[:, free]
        if np.all((p - o[0]) @ z[0] > 0) and (p - o[1]) @ z[1] > 0:
            converge_sign = 1.0 if delta > 0 else -1.0  # eyes converge for +delta
            return bool(np.linalg.eigvalsh(J.T @ J)[0] <= NULL_EIGENVALUE), converge_sign
    return False, converge_sign


__all__ = [
    "MIN_TARGET_DISTANCE",
    "NULL_EIGENVALUE",
    "SCALED_DISTANCE",
    "FixationState",
    "closest_point",
    "evaluate_fixation",
    "fixation_jacobian",
    "fixation_redundancy",
    "pointing_errors",
    "target_point",
]
