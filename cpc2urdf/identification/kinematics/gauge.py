"""Frames stay on the parts: choose what the data cannot see as close to the nominal model as possible.

Measurements of frames at the ends of a tree cannot see every constant of a CPC model
(DESIGN.md, "Calibrated URDFs that look like the robot"). These *gauge* transformations change
no frame's pose in world at any configuration:

- the base split: ``T_world_base <- T_world_base G_b`` and every constant on the base
  ``c <- G_b^-1 c``, any ``G_b`` in SE(3) (6 freedoms);
- a revolute joint j: its axis constant ``E_j <- E_j G_j`` and every constant on its link
  ``c <- G_j^-1 c``, with ``G_j = Rot(z, a) Trans(0, 0, s)`` (where the axis frame sits along the
  axis and how it is turned about it: 2 freedoms), because ``G_j`` commutes with ``Rot(z, q)``
  (eq. (6)), so the link frame moves to ``T_world_link G_j`` and everything after it is unchanged;
- a prismatic joint j: the same with ``G_j = Rot(z, a) Trans(x, y, s)`` (4 freedoms), which
  commutes with ``Trans(0, 0, q)``.

That is 6 + 2 n_R + 4 n_P freedoms, exactly what the minimal parametrisation removes
(:mod:`parametrization`: 4 per revolute axis line, 2 per prismatic direction). An identification
fixes them arbitrarily (the closed form puts frames where its algebra lands, metres away from the
parts), so :func:`align_to_nominal` chooses them by least squares: every joint's link frame, in base
coordinates, as close as possible to the nominal model's at a set of configurations (positions in
metres, rotations in radians times :data:`ROTATION_LENGTH`). Measured frames are untouched to
rounding; a URDF written from the result puts each link (and its mesh) where the part is.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from cpc2urdf.model import BASE, CPCModel, CPCParams
from cpc2urdf.transforms import Array, inverse

ROTATION_LENGTH = 0.1  # [m]: a link frame turned by 1 rad counts as 0.1 m off
ALIGN_CONFIGURATIONS = (
    8  # configurations compared: the middle of the calibration box and 7 seeded draws
)
# Residual evaluations the alignment may take. A model of consistent data converges in a few dozen
# (IIS-head: 22-34); a model far from every gauge of the nominal one (data read in the wrong unit,
# which the consistency gate then refuses) creeps on for thousands without converging (scipy's
# default cap, 100 per gauge freedom: ~11 s on the IIS-head), for a cosmetic choice.
ALIGN_MAX_EVALUATIONS = 400


def _rz(a: float) -> Array:
    c, s = np.cos(a), np.sin(a)
    return np.array(
        [[c, -s, 0.0, 0.0], [s, c, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
    )


def _trans(x: float, y: float, z: float) -> Array:
    T = np.eye(4)
    T[:3, 3] = x, y, z
    return T


def gauge_size(model: CPCModel) -> int:
    """Number of gauge freedoms of ``model``'s tree: 6 + 2 per revolute + 4 per prismatic joint."""
    return 6 + sum(2 if j.type == "revolute" else 4 for j in model.structure.joints)


def gauge_transforms(model: CPCModel, g: ArrayLike) -> tuple[Array, dict[str, Array]]:
    """``(G_base, {joint: G_j})`` for the gauge vector ``g`` (module docstring), shape (K,):
    base rotation vector [rad] and translation [m], then per joint ``a`` [rad], ``s`` [m]
    (revolute) or ``a``, ``x``, ``y``, ``s`` (prismatic)."""
    g = np.asarray(g, dtype=float)
    G_base = np.eye(4)
    G_base[:3, :3] = Rotation.from_rotvec(g[:3]).as_matrix()
    G_base[:3, 3] = g[3:6]
    out: dict[str, Array] = {}
    k = 6
    for j in model.structure.joints:
        if j.type == "revolute":
            out[j.name] = _rz(g[k]) @ _trans(0.0, 0.0, g[k + 1])
            k += 2
        else:
            out[j.name] = _rz(g[k]) @ _trans(g[k + 1], g[k + 2], g[k + 3])
            k += 4
    return G_base, out


def apply_gauge(model: CPCModel, g: ArrayLike) -> CPCModel:
    """``model`` moved along its gauge by ``g``: every frame's world pose is unchanged, every
    joint's link frame becomes ``T_world_link G_j``."""
    G_base, G = gauge_transforms(model, g)
    s = model.structure

    def parent_g(parent: str) -> Array:
        return G_base if parent == BASE else G[parent]

    joints = {
        j.name: CPCParams.from_matrix(
            inverse(parent_g(j.parent)) @ model.joints[j.name].matrix() @ G[j.name]
        )
        for j in s.joints
    }
    frames = {
        f.name: CPCParams.from_matrix(inverse(parent_g(f.parent)) @ model.frames[f.name].matrix())
        for f in s.frames
    }
    world_to_base = CPCParams.from_matrix(model.world_to_base.matrix() @ G_base)
    return model.with_params(world_to_base=world_to_base, joints=joints, frames=frames)


def _base_link_poses(model: CPCModel, q: Array) -> Array:
    """Every joint's link frame in base coordinates, shape (N, n, 4, 4)."""
    _, link = model.link_poses(q)
    return np.einsum("ij,nkjl->nkil", inverse(model.world_to_base.matrix()), link)


def align_to_nominal(
    model: CPCModel, nominal: CPCModel, q: ArrayLike | None = None, *, seed: int = 0
) -> CPCModel:
    """``model`` with its gauge chosen so that its link frames (in base coordinates) are as close
    as possible to ``nominal``'s (module docstring); measured frames unchanged.

    Args:
        model: An identified model.
        nominal: The nominal model of the same tree (the spec's geometry, or the user's URDF).
        q: Configurations to compare at [rad]/[m], shape (N, n); default: the middle of the
            calibration box and seeded draws inside it.
        seed: Seed of the default draws.
    """
    s = model.structure
    if s.joint_names != nominal.structure.joint_names:
        raise ValueError("align_to_nominal needs the same joints in both models")
    if q is None:
        box = s.calibration_ranges()
        rng = np.random.default_rng(seed)
        draws = rng.uniform(box[:, 0], box[:, 1], size=(ALIGN_CONFIGURATIONS - 1, s.n_joints))
        qq = np.vstack([box.mean(axis=1), draws])
    else:
        qq = np.atleast_2d(np.asarray(q, dtype=float))
    A = _base_link_poses(model, qq)
    target = _base_link_poses(nominal, qq)
    target_rot_inv = np.swapaxes(target[..., :3, :3], -1, -2)
    kinds = [j.type == "revolute" for j in s.joints]

    def residuals_of(g: Array) -> Array:
        """The residuals at each row of ``g`` (m, K): shape (m, R), in one vectorised pass."""
        m = len(g)
        G_base_inv = np.zeros((m, 4, 4))
        R = Rotation.from_rotvec(g[:, :3]).as_matrix()
        G_base_inv[:, :3, :3] = np.swapaxes(R, -1, -2)
        G_base_inv[:, :3, 3] = -np.einsum("mji,mj->mi", R, g[:, 3:6])
        G_base_inv[:, 3, 3] = 1.0
        Gj = np.zeros(
            (m, len(kinds), 4, 4)
        )  # Rot(z, a) Trans(x, y, s) (x = y = 0 for a revolute joint)
        k = 6
        for i, revolute in enumerate(kinds):
            a = g[:, k]
            x, y, z = (
                (np.zeros(m), np.zeros(m), g[:, k + 1])
                if revolute
                else (g[:, k + 1], g[:, k + 2], g[:, k + 3])
            )
            c, sn = np.cos(a), np.sin(a)
            Gj[:, i, 0, 0], Gj[:, i, 0, 1], Gj[:, i, 1, 0], Gj[:, i, 1, 1] = c, -sn, sn, c
            Gj[:, i, 0, 3], Gj[:, i, 1, 3], Gj[:, i, 2, 3] = c * x - sn * y, sn * x + c * y, z
            Gj[:, i, 2, 2] = Gj[:, i, 3, 3] = 1.0
            k += 2 if revolute else 4
        B = np.einsum("mij,nkjl,mklp->mnkip", G_base_inv, A, Gj)
        dp = B[..., :3, 3] - target[..., :3, 3]
        dR = np.einsum("nkij,mnkjl->mnkil", target_rot_inv, B[..., :3, :3])
        rv = Rotation.from_matrix(dR.reshape(-1, 3, 3)).as_rotvec().reshape(dp.shape)
        return np.concatenate([dp.reshape(m, -1), ROTATION_LENGTH * rv.reshape(m, -1)], axis=1)

    def residuals(g: Array) -> Array:
        return residuals_of(g[None])[0]

    def jacobian(g: Array) -> Array:
        """Forward differences with scipy's default '2-point' steps, all columns in one pass (the
        same Jacobian as ``least_squares``' own, ~20x cheaper: the residuals are Python-bound)."""
        h = np.finfo(float).eps ** 0.5 * np.where(g >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(g))
        X = g + np.diag(h)
        dx = np.diagonal(X) - g  # the step actually taken (representable)
        F = residuals_of(np.vstack([g[None], X]))
        return ((F[1:] - F[0]) / dx[:, None]).T

    sol = least_squares(
        residuals,
        np.zeros(gauge_size(model)),
        jac=jacobian,
        method="lm",
        xtol=1e-14,
        ftol=1e-14,
        max_nfev=ALIGN_MAX_EVALUATIONS,
    )
    return apply_gauge(model, sol.x)


__all__ = [
    "ALIGN_CONFIGURATIONS",
    "ALIGN_MAX_EVALUATIONS",
    "ROTATION_LENGTH",
    "align_to_nominal",
    "apply_gauge",
    "gauge_size",
    "gauge_transforms",
]
