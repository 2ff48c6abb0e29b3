"""A minimal, smooth parametrisation of a CPC tree for the frames that were measured.

Which geometry can pose measurements of some frames determine? Every joint on the path from
``base`` to a measured frame contributes its axis, and every measured frame its pose on its
link; everything else is *gauge*: it moves frames that nobody observes and is absorbed exactly by
the constants of the next frames down the tree. Counting (the CPC model of Shih et al. sec. 2.2,
Table 1, generalised to a tree; it is also the count of a product-of-exponentials model):

- a revolute joint: its axis *line*, 4 parameters (direction 2, position across the line 2);
- a prismatic joint: its axis *direction*, 2 parameters (a translation commutes with the slide);
- a measured frame: its pose on its link, 6 parameters.

For the IIS-head (2 prismatic, 4 revolute joints, 2 plates) that is 2*2 + 4*4 + 2*6 = 32: the
tilt axis is one line shared by both branches. The paper's model (eq. (11)) gives the right branch
its own ``l_3R`` on the tilt axis and has 34 parameters; 2 of them are redundant (docs/identification.md).

Gauge (fixed, not estimated): ``T_world_base``; for a revolute joint, its axis frame's rotation
about and translation along its own axis (``beta``, ``l_z``); for a prismatic joint, its axis
frame's rotation about its axis and its whole origin (``beta``, ``l``). These stay at the values of
the *reference* model the chart is built around (e.g. the closed-form estimate).

The chart: a parameter vector ``x`` is a *local* CPC update of each placement ``E`` (eq. (3)) of
the reference model::

    E(x) = E_ref @ R(db) @ Rot(z, dbeta) @ Trans(dl)     # eq. (3), applied on the right

with ``db = (db_x, db_y, sqrt(1 - db_x^2 - db_y^2))`` as in eq. (4). Revolute joints use
``(b_x, b_y, l_x, l_y)``, prismatic joints ``(b_x, b_y)``, measured frames all six
``(b_x, b_y, beta, l_x, l_y, l_z)``; ``x = 0`` is the reference model. Because the update starts
at the identity, the chart is smooth around the reference even where the paper's own ``(b_x,
b_y)`` coordinates are singular (``b_z = 0``, i.e. consecutive axes at right angles, as for most
of the IIS-head). Parameter names are ``"<joint or frame>.<b_x|b_y|beta|l_x|l_y|l_z>"``, e.g.
``"tilt.b_x"``, ``"plate_left.l_z"``; units are [rad] for ``b_*``/``beta`` and [m] for ``l_*``.

:meth:`Parametrization.pose_jacobian` gives the derivative of every measured frame's world pose
with respect to ``x`` in closed form (spatial twists), which :mod:`refine` and
:mod:`uncertainty` build on.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.model import BASE, CPCModel, CPCParams
from cpc2urdf.transforms import Array, cpc_rotation, rotation_z

# Free local parameters per kind of placement (Table 1 of Shih et al. with the gauge removed).
REVOLUTE_PARAMS: tuple[str, ...] = ("b_x", "b_y", "l_x", "l_y")
PRISMATIC_PARAMS: tuple[str, ...] = ("b_x", "b_y")
FRAME_PARAMS: tuple[str, ...] = ("b_x", "b_y", "beta", "l_x", "l_y", "l_z")
_SLOT = {"b_x": 0, "b_y": 1, "beta": 2, "l_x": 3, "l_y": 4, "l_z": 5}
# A local update must keep db_z > 0; beyond this |db| the chart is re-centred by the caller.
MAX_LOCAL_TILT = 0.95  # [-]: |(db_x, db_y)|


@dataclass(frozen=True)
class Block:
    """The free parameters of one placement (a joint's axis frame or a measured frame).

    Attributes:
        owner: Joint or frame name.
        kind: ``"revolute"``, ``"prismatic"`` or ``"frame"``.
        start: Index of the first parameter in the vector.
        params: Local parameter names, e.g. ``("b_x", "b_y", "l_x", "l_y")``.
    """

    owner: str
    kind: str
    start: int
    params: tuple[str, ...]

    @property
    def slice(self) -> slice:
        return slice(self.start, self.start + len(self.params))


def local_update(values: ArrayLike, params: Sequence[str]) -> Array:
    """The (4, 4) local CPC update ``R(db) Rot(z, dbeta) Trans(dl)`` of a block's values."""
    full = np.zeros(6)
    for v, p in zip(np.asarray(values, dtype=float), params, strict=True):
        full[_SLOT[p]] = v
    return _update_matrix(full)


def _update_matrix(full: Array) -> Array:
    bx, by, beta = full[0], full[1], full[2]
    s2 = bx * bx + by * by
    if s2 >= MAX_LOCAL_TILT**2:
        raise DegenerateDataError(
            f"local axis update |(b_x, b_y)| = {np.sqrt(s2):.3g} is too large for the chart "
            f"(max {MAX_LOCAL_TILT}); re-centre it on a closer model"
        )
    R = cpc_rotation((bx, by, np.sqrt(1.0 - s2))) @ rotation_z(beta)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = R @ full[3:]
    return T


def _local_twists(full: Array) -> Array:
    """Body twists ``Delta^-1 dDelta/dp`` of the six local parameters at ``full``, shape (6, 6).

    Row k is ``(v, w)`` (translation, rotation) in the frame *after* the update, for parameter
    k of ``(b_x, b_y, beta, l_x, l_y, l_z)``.
    """
    bx, by, beta = full[0], full[1], full[2]
    l = full[3:]
    bz = np.sqrt(1.0 - bx * bx - by * by)
    c = 1.0 + bz
    R = cpc_rotation((bx, by, bz))
    Rz = rotation_z(beta)
    out = np.zeros((6, 6))
    for k, (dbx, dby) in enumerate(((1.0, 0.0), (0.0, 1.0))):
        dbz = -(bx * dbx + by * dby) / bz
        dc = dbz
        dR = np.array(  # derivative of eq. (4) with b_z = sqrt(1 - b_x^2 - b_y^2)
            [
                [
                    -2 * bx * dbx / c + bx * bx * dc / c**2,
                    -(dbx * by + bx * dby) / c + bx * by * dc / c**2,
                    dbx,
                ],
                [
                    -(dbx * by + bx * dby) / c + bx * by * dc / c**2,
                    -2 * by * dby / c + by * by * dc / c**2,
                    dby,
                ],
                [-dbx, -dby, dbz],
            ]
        )
        W = R.T @ dR  # skew: the body angular velocity of R(b) before Rot(z, beta)
        w = Rz.T @ np.array([W[2, 1] - W[1, 2], W[0, 2] - W[2, 0], W[1, 0] - W[0, 1]]) / 2.0
        out[k] = np.concatenate([np.cross(w, l), w])
    z = np.array([0.0, 0.0, 1.0])
    out[2] = np.concatenate([np.cross(z, l), z])
    out[3:, :3] = np.eye(3)
    return out


class Parametrization:
    """Minimal local coordinates of a CPC model's geometry as seen through some frames.

    Args:
        reference: The model the chart is centred on (``x = 0``); its gauge is kept.
        frames: The measured frames; joints on their paths get parameters. Default: all frames
            of kind ``"plate"``.

    Attributes:
        blocks: One :class:`Block` per parametrised joint (topological order) then per frame.
        names: ``"<owner>.<param>"`` for every entry of the vector.
        units: ``"rad"`` or ``"m"`` for every entry.
        joints: Parametrised joint names (those on a path to a measured frame).
        frames: The measured frames.
    """

    def __init__(self, reference: CPCModel, frames: Iterable[str] | None = None) -> None:
        s = reference.structure
        if frames is None:
            frames = [f.name for f in s.frames if f.kind == "plate"]
        self.frames: tuple[str, ...] = tuple(frames)
        if not self.frames:
            raise DegenerateDataError("nothing to identify: no measured frames")
        for f in self.frames:
            s.frame(f)  # UnknownNameError for a typo
        on_path = {j for f in self.frames for j in s.path_to(f)}
        self.joints: tuple[str, ...] = tuple(n for n in s.joint_names if n in on_path)
        self.reference = reference
        blocks: list[Block] = []
        k = 0
        for n in self.joints:
            kind = s.joint(n).type
            params = REVOLUTE_PARAMS if kind == "revolute" else PRISMATIC_PARAMS
            blocks.append(Block(n, kind, k, params))
            k += len(params)
        for f in self.frames:
            blocks.append(Block(f, "frame", k, FRAME_PARAMS))
            k += len(FRAME_PARAMS)
        self.blocks: tuple[Block, ...] = tuple(blocks)
        self.names: tuple[str, ...] = tuple(f"{b.owner}.{p}" for b in blocks for p in b.params)
        self.units: tuple[str, ...] = tuple(
            "m" if p.startswith("l_") else "rad" for b in blocks for p in b.params
        )
        self._block = {b.owner: b for b in blocks}
        # Which parametrised joints lie above each measured frame (their parameters move it).
        self._upstream = {f: set(s.path_to(f)) for f in self.frames}

    @property
    def n_params(self) -> int:
        return len(self.names)

    def block(self, owner: str) -> Block:
        return self._block[owner]

    def index(self, name: str) -> int:
        """Position of parameter ``name`` (e.g. ``"tilt.b_x"``) in the vector."""
        return self.names.index(name)

    def gauge_description(self) -> str:
        """One paragraph saying what is held fixed (for reports and model files)."""
        return (
            "fixed at the reference model: world_to_base (6); each revolute joint's axis-frame "
            "rotation about and offset along its axis (beta, l_z); each prismatic joint's "
            "axis-frame rotation about its axis and its origin (beta, l)"
        )

    def counts(self) -> dict[str, int]:
        """Parameter count per kind: revolute, prismatic, frame, and total."""
        c = {"revolute": 0, "prismatic": 0, "frame": 0}
        for b in self.blocks:
            c[b.kind] += len(b.params)
        c["total"] = self.n_params
        return c

    # ---- conversions ---------------------------------------------------------------------------

    def _full(self, x: Array, b: Block) -> Array:
        full = np.zeros(6)
        for p, v in zip(b.params, x[b.slice], strict=True):
            full[_SLOT[p]] = v
        return full

    def model_from_vector(self, x: ArrayLike) -> CPCModel:
        """The model at local coordinates ``x`` (shape (n_params,)); ``x = 0`` is the reference.

        Unparametrised joints and frames (not on a measured path) keep the reference values.
        """
        x = self._check(x)
        ref = self.reference
        joints: dict[str, CPCParams] = {}
        frames: dict[str, CPCParams] = {}
        for b in self.blocks:
            E_ref = (ref.joints[b.owner] if b.kind != "frame" else ref.frames[b.owner]).matrix()
            params = CPCParams.from_matrix(E_ref @ _update_matrix(self._full(x, b)))
            (frames if b.kind == "frame" else joints)[b.owner] = params
        return ref.with_params(joints=joints, frames=frames)

    # Alias with the name the issue uses.
    params_from_vector = model_from_vector

    def vector_from_model(self, model: CPCModel) -> Array:
        """Local coordinates of ``model``'s geometry in this chart (gauge-aligned first).

        ``model`` may use any gauge (its own ``T_world_base``, ``beta``/``l_z`` on revolute axes,
        origins of prismatic axis frames): only what the measured frames can see is compared, so
        ``model_from_vector(vector_from_model(m))`` has the same forward kinematics as ``m`` for
        every measured frame and the same joint axis lines, at every configuration.

        Raises:
            DegenerateDataError: ``model`` is too far from the reference for this chart (an axis
                turned by more than ~70 degrees, or reversed).
        """
        s = self.reference.structure
        if model.structure.joint_names != s.joint_names:
            raise DegenerateDataError(
                f"models differ in joints: {list(model.structure.joint_names)} vs {list(s.joint_names)}"
            )
        q0 = np.zeros(s.n_joints)
        axis_m, _ = model.link_poses(q0)
        T_m = model.fk(q0, self.frames)
        # Walk down the tree building the aligned model's axis frames at q = 0 (link = axis there).
        aligned_link: dict[str, Array] = {BASE: self.reference.T_world_base()}
        x = np.zeros(self.n_params)
        for b in self.blocks:
            if b.kind == "frame":
                parent = s.frame(b.owner).parent
                E_ref = self.reference.frames[b.owner].matrix()
                target = T_m[b.owner]
            else:
                parent = s.joint(b.owner).parent
                E_ref = self.reference.joints[b.owner].matrix()
                target = axis_m[0, s.joint_index(b.owner)]
            X = np.linalg.solve(aligned_link[parent] @ E_ref, target)  # the needed local update
            b_loc = X[:3, 2]
            if b_loc[2] <= np.sqrt(1.0 - MAX_LOCAL_TILT**2):
                raise DegenerateDataError(
                    f"{b.owner}: axis differs from the reference by {np.degrees(np.arccos(np.clip(b_loc[2], -1, 1))):.1f} deg, "
                    "outside this chart"
                )
            Rb = cpc_rotation(b_loc)
            full = np.zeros(6)
            full[:2] = b_loc[:2]
            if b.kind == "frame":
                Rz = Rb.T @ X[:3, :3]
                full[2] = np.arctan2(Rz[1, 0], Rz[0, 0])
                full[3:] = X[:3, :3].T @ X[:3, 3]
            elif b.kind == "revolute":
                # Gauge: rotate about / slide along the axis so that beta = l_z = 0 locally.
                full[3:5] = (Rb.T @ X[:3, 3])[:2]
            for p in b.params:
                x[b.start + b.params.index(p)] = full[_SLOT[p]]
            if b.kind != "frame":
                aligned_link[b.owner] = aligned_link[parent] @ E_ref @ _update_matrix(full)
        return x

    def _check(self, x: ArrayLike) -> Array:
        x = np.asarray(x, dtype=float)
        if x.shape != (self.n_params,):
            raise ValueError(f"parameter vector must have shape ({self.n_params},), got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise DegenerateDataError("parameter vector contains NaN or inf")
        return x

    # ---- derivatives ---------------------------------------------------------------------------

    def pose_jacobian(
        self, x: ArrayLike, q: ArrayLike
    ) -> tuple[dict[str, Array], dict[str, Array]]:
        """World poses of the measured frames and their derivatives with respect to ``x``.

        Args:
            x: Local coordinates, shape (n_params,).
            q: Configurations [rad]/[m], shape (N, n) in ``structure.joint_names`` order.

        Returns:
            ``(T, D)``: ``T[frame]`` is ``T_world_frame`` of shape (N, 4, 4); ``D[frame]`` of
            shape (N, 6, n_params) holds, per parameter, the first-order change of the frame's
            origin (rows 0-2, [m] per unit parameter) and of its orientation as a rotation
            vector in world (rows 3-4-5, ``dR = [w]x R``, [rad] per unit parameter).
        """
        x = self._check(x)
        model = self.model_from_vector(x)
        s = model.structure
        qq = np.atleast_2d(np.asarray(q, dtype=float))
        axis, _ = model.link_poses(qq)
        T = model.fk(qq, self.frames)
        N = qq.shape[0]
        D = {f: np.zeros((N, 6, self.n_params)) for f in self.frames}
        for b in self.blocks:
            xi = _local_twists(self._full(x, b))[[_SLOT[p] for p in b.params]]  # (k, 6) body twists
            if b.kind == "frame":
                A = T[b.owner]
                targets = [b.owner]
            else:
                A = axis[:, s.joint_index(b.owner)]
                targets = [f for f in self.frames if b.owner in self._upstream[f]]
            R, p = A[:, :3, :3], A[:, :3, 3]
            w_s = np.einsum("nij,kj->nki", R, xi[:, 3:])  # spatial angular velocity (N, k, 3)
            v_s = np.einsum("nij,kj->nki", R, xi[:, :3])  # translation part at A's origin
            for f in targets:
                lever = T[f][:, None, :3, 3] - p[:, None, :]  # from A's origin to the frame's
                dp = v_s + np.cross(w_s, lever)
                D[f][:, :3, b.slice] = np.swapaxes(dp, 1, 2)
                D[f][:, 3:, b.slice] = np.swapaxes(w_s, 1, 2)
        return T, D


__all__ = [
    "FRAME_PARAMS",
    "PRISMATIC_PARAMS",
    "REVOLUTE_PARAMS",
    "Block",
    "Parametrization",
    "local_update",
]
