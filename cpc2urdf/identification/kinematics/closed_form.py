"""Closed-form CPC identification of a tree of revolute and prismatic joints (Shih et al. sec. 4.2).

Input: one-joint-at-a-time measurements (:mod:`cpc2urdf.identification.kinematics.protocol`) of the poses
``T_world_F`` of the measured frames F (the plates, one per branch or more). No nominal model.
Output: a :class:`~cpc2urdf.model.CPCModel` of the same tree that reproduces the measured frames'
forward kinematics (exactly, on noise-free data).

The paper's three steps, generalised from the IIS-head to any tree:

**Step 1, rotations (leaves to root; eqs. (29)-(57)).** Every link j (and the base) gets its
*elements*: the measured frames fixed to it and the child joints that move a measured frame.
Each element e brings a frame ``A_e`` rigidly fixed to link j whose world rotation is known in
every record from the measurements: the measured frame itself, or the child's axis frame (the
child's link frame rotated back by its reading). For a revolute joint j:

- for each element, the direction ``d`` of j's axis in ``A_e`` is the null vector of the stacked
  ``[C_k - I]`` with ``C_k = ^{A}R_w(q0) ^{A}R_w(q_jk)^T`` (eqs. (32)-(35), (39)-(41)), one block
  per record of j's sweep *and per measured frame below e* (eq. (52) combines the two branches
  this way for the pan joint). Its sign follows the reading: ``C_k`` turns by ``q_jk - q_j0``
  about ``d``, so ``vee(C_k - C_k^T) = 2 sin(q_jk - q_j0) d``. The paper's ``b_z >= 0`` would
  instead flip the sign of the joint variable, which a model of raw transducer readings cannot.
- the link frame of j is ``A_e0 R(b)^T`` for the first element (eq. (4), ``b = (-d_x, -d_y, d_z)``
  from eq. (34)); every other element's own estimate of the link frame differs by a rotation
  ``Rot(z, beta)`` about the shared axis, found by eqs. (42)-(45) (the paper's ``beta_3``).

A prismatic joint (and the base) does not rotate: its elements are aligned by their measured
relative rotation (a chordal mean over the records), and its direction is left to Step 2. The
base's world rotation is the chordal mean of every record's and branch's estimate (eqs. (55),
(57), which use one record and one branch at a time).

**Step 2, translations (eqs. (58)-(64)).** With every rotation known as a function of ``q``, the
measured origins are linear in: each revolute joint's in-plane offset ``(l_x, l_y)`` (its axis
frame origin relative to its parent link, perpendicular to its axis; ``l_z = 0``), each prismatic
joint's direction ``u`` (the paper's ``^w r_{0,z}``, ``^w r_{1,z}`` generalised to prismatic joints
anywhere in the tree), and each measured frame's ``l`` (3). One linear least-squares system over
all records and branches gives them; ``|u| = 1`` is then enforced and the offsets re-solved with
``u`` fixed. The base origin is redundant (every path absorbs it); as in eq. (58) it is put on the
first revolute axis below the base (the foot of the perpendicular from the world origin, at zero
readings of any prismatic joints above it).

**Step 3, base and prismatic frames (eqs. (65)-(67)).** A prismatic joint's axis frame is its
child's frame turned by ``R(b)^T`` with ``b' = u`` (eqs. (65), (66)); the base frame is the axis
frame of its first element (the paper's frame 0, with ``R_0``, ``beta_0`` of eq. (14)).

In a tree, a joint shared by several branches (the head's tilt) has ONE axis line: its offset
unknowns are shared by all branches in Step 2, where the paper's eq. (11) gives each branch its
own ``l_3`` (34 parameters instead of 32; see :func:`count_parameters`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.protocol import Protocol, recognise_protocol
from cpc2urdf.model import BASE, CPCModel, CPCParams, RobotStructure
from cpc2urdf.model_metadata import Provenance
from cpc2urdf.transforms import (
    Array,
    cpc_rotation,
    homogeneous,
    inverse,
    project_to_rotation,
    rot_z,
    rotation_z,
)

METHOD = "closed-form"
# Below this, a singular value of a stacked system counts as zero (entries are O(1): rotation
# matrix entries, and lengths of order 1 m).
RANK_TOL = 1e-9


def _vee(S: Array) -> Array:
    """``vee(S - S^T)`` of (..., 3, 3): twice the axis times the sine of a rotation's angle."""
    return np.stack(
        [S[..., 2, 1] - S[..., 1, 2], S[..., 0, 2] - S[..., 2, 0], S[..., 1, 0] - S[..., 0, 1]],
        axis=-1,
    )


def _t(R: Array) -> Array:
    return np.swapaxes(R, -1, -2)


def b_from_direction(d: Array) -> Array:
    """Eq. (34): the CPC vector ``b`` whose ``R(b)`` has ``d = [-b_x, -b_y, b_z]`` as third row.

    ``d`` is the parent's axis expressed in the child frame; ``R(b)^T z = d``.
    """
    return np.array([-d[0], -d[1], d[2]]) / np.linalg.norm(d)


@dataclass
class _Element:
    name: str  # a measured frame or a child joint
    is_frame: bool
    frames: tuple[str, ...]  # measured frames at or below it


@dataclass
class ClosedFormDetails:
    """Intermediate results, for reports and tests.

    Attributes:
        axis_in_element: Revolute joint -> {element: unit direction ``d`` of its axis in that
            element's frame (eq. (35))}.
        beta: Revolute joint -> {element: ``beta`` [rad] aligning it to the first element
            (eq. (45))}.
        prismatic_norm: Prismatic joint -> ``|u|`` before normalisation (1 on exact data).
        translation_rms: RMS residual of the linear system of eq. (64) [m].
        notes: Human-readable remarks (frames carried over or dropped, axes with ``b_z < 0``).
    """

    axis_in_element: dict[str, dict[str, Array]] = field(default_factory=dict)
    beta: dict[str, dict[str, float]] = field(default_factory=dict)
    prismatic_norm: dict[str, float] = field(default_factory=dict)
    translation_rms: float = 0.0
    notes: list[str] = field(default_factory=list)


class _Solver:
    """One identification run; the steps are methods so each reads as the paper's text."""

    def __init__(self, ms: MeasurementSet, protocol: Protocol, shared_axes: bool = True) -> None:
        self.shared_axes = shared_axes
        self.ms = ms
        self.s: RobotStructure = ms.structure
        self.p = protocol
        self.q = ms.q
        self.N = ms.n_records
        self.valid = {f: ms.has_pose(f) for f in protocol.frames}
        self.R_meas = {f: ms.poses[f][:, :3, :3] for f in protocol.frames}
        self.p_meas = {f: ms.poses[f][:, :3, 3] for f in protocol.frames}
        self.details = ClosedFormDetails()
        # ^{L_parent}R_{A_x}: rotation of element x's frame on its parent link. For a prismatic
        # joint, A_x and the link frame are provisional until Step 3 knows its direction.
        self.rot_in_parent: dict[str, Array] = {}
        self.elements: dict[str, list[_Element]] = {}
        # World rotation of each link frame as estimated through each measured frame below it,
        # shape (N, 3, 3) per frame, NaN where that frame is missing.
        self.W_link: dict[str, dict[str, Array]] = {}

    # ---- Step 1: rotations ----------------------------------------------------------------------

    def _elements_of(self, node: str) -> list[_Element]:
        measured = set(self.p.frames)
        out = [
            _Element(f.name, True, (f.name,))
            for f in self.s.frames
            if f.parent == node and f.name in measured
        ]
        out += [_Element(c.name, False, self.p.frames_below[c.name]) for c in self.s.children(node)]
        return out

    def _element_rotations(self, e: _Element) -> dict[str, Array]:
        """``^wR_{A_e}`` per measured frame below e, shape (N, 3, 3)."""
        if e.is_frame:
            return {e.name: self.R_meas[e.name]}
        W = self.W_link[e.name]
        if self.s.joint(e.name).type == "revolute":
            Rz_t = _t(rot_z(self.q[:, self.s.joint_index(e.name)])[:, :3, :3])
            return {f: w @ Rz_t for f, w in W.items()}  # axis frame = link frame @ Rot(z, -q)
        return W

    def _axis_direction(self, joint: str, e: _Element, WA: dict[str, Array]) -> Array:
        """Eqs. (32)-(35): joint's axis in ``A_e``, the null vector of the stacked ``[C_k - I]``."""
        ji = self.s.joint_index(joint)
        blocks, vees, sines = [], [], []
        for f, W in WA.items():
            v = self.valid[f]
            ref = [r for r in self.p.reference if v[r]]
            sweep = [k for k in self.p.sweeps[joint] if v[k]]
            for r in ref:
                # eq. (32): C_k = ^AR_w(q_0) ^AR_w(q_k)^{-1} = W_r^T W_k
                C = W[r].T @ W[sweep]
                blocks.append(C - np.eye(3))
                vees.append(_vee(C))
                sines.append(np.sin(self.q[sweep, ji] - self.q[r, ji]))
        if not blocks:
            raise DegenerateDataError(
                f"joint {joint!r}: no record of its sweep measured a frame below {e.name!r} "
                f"({', '.join(e.frames)}) together with a reference record"
            )
        A = np.concatenate(blocks).reshape(-1, 3)
        _, S, Vt = np.linalg.svd(A, full_matrices=False)  # eq. (35): smallest singular vector
        if S[1] < RANK_TOL:
            raise DegenerateDataError(
                f"joint {joint!r}: its measured rotations do not determine its axis (every sweep "
                "reading turns it by a multiple of 360 degrees?)"
            )
        d = Vt[-1]
        # Sign from the reading: C_k turns by (q_k - q_0) about d, vee(C_k - C_k^T) = 2 sin(dq) d.
        score = float(np.sum(np.concatenate(sines) * (np.concatenate(vees) @ d)))
        if abs(score) < RANK_TOL:
            raise DegenerateDataError(
                f"joint {joint!r}: every sweep reading differs from q0 by a multiple of 180 degrees, "
                "which cannot tell the direction in which its reading increases"
            )
        return d if score > 0 else -d

    def _beta(
        self,
        joint: str,
        e0: _Element,
        R0: Array,
        e: _Element,
        Re: Array,
        WA0: dict[str, Array],
        WA: dict[str, Array],
    ) -> float:
        """Eqs. (42)-(45): ``^{L0}R_w = Rot(z, beta) ^{Le}R_w`` over all records both branches saw.

        The columns of eq. (45)'s matrix are orthogonal with equal norms, so the least-squares
        ``[cos, sin]`` normalised to ``sin^2 + cos^2 = 1`` is the exact constrained optimum.
        """
        num_c = num_s = 0.0
        seen = False
        for f0, W0 in WA0.items():
            for f, W in WA.items():
                both = self.valid[f0] & self.valid[f]
                if not both.any():
                    continue
                seen = True
                a = R0 @ _t(W0[both])  # ^{L_j}R_w through branch e0, eq. (43)
                b = Re @ _t(W[both])  # the same through branch e
                num_c += float(np.sum(b[:, 0, :] * a[:, 0, :] + b[:, 1, :] * a[:, 1, :]))
                num_s += float(np.sum(-b[:, 1, :] * a[:, 0, :] + b[:, 0, :] * a[:, 1, :]))
        if not seen:
            raise DegenerateDataError(
                f"joint {joint!r}: branches {e0.name!r} and {e.name!r} were never measured in the same "
                "record, so their relative orientation about the shared axis (beta, eq. (45)) is unknown"
            )
        return math.atan2(num_s, num_c)

    def _relative_rotation(
        self, node: str, e0: _Element, e: _Element, WA0: dict[str, Array], WA: dict[str, Array]
    ) -> Array:
        """``^{A_e0}R_{A_e}`` of two elements on one non-rotating link: chordal mean over records."""
        acc = np.zeros((3, 3))
        seen = False
        for f0, W0 in WA0.items():
            for f, W in WA.items():
                both = self.valid[f0] & self.valid[f]
                if both.any():
                    seen = True
                    acc += np.sum(_t(W0[both]) @ W[both], axis=0)
        if not seen:
            raise DegenerateDataError(
                f"{'the base' if node == BASE else f'joint {node!r}'}: branches {e0.name!r} and {e.name!r} "
                "were never measured in the same record, so their relative orientation is unknown"
            )
        return project_to_rotation(acc)

    def step1_rotations(self) -> None:
        """Leaves to root: axis directions, link frames, branch alignment (eqs. (29)-(57))."""
        for node in [*reversed(self.s.joint_names), BASE]:
            elems = self._elements_of(node)
            self.elements[node] = elems
            if not elems:
                continue
            WA = {e.name: self._element_rotations(e) for e in elems}
            e0 = elems[0]
            revolute = node != BASE and self.s.joint(node).type == "revolute"
            if revolute:
                dirs = {e.name: self._axis_direction(node, e, WA[e.name]) for e in elems}
                self.details.axis_in_element[node] = dirs
                self.details.beta[node] = {}
                R0 = cpc_rotation(b_from_direction(dirs[e0.name]))  # eq. (4) with eq. (34)
                self.rot_in_parent[e0.name] = R0
                for e in elems[1:]:
                    Re = cpc_rotation(b_from_direction(dirs[e.name]))
                    beta = self._beta(node, e0, R0, e, Re, WA[e0.name], WA[e.name])
                    self.details.beta[node][e.name] = beta
                    self.rot_in_parent[e.name] = rotation_z(beta) @ Re  # eq. (11)'s Rot(z, beta_3)
            else:
                self.rot_in_parent[e0.name] = np.eye(3)
                for e in elems[1:]:
                    self.rot_in_parent[e.name] = self._relative_rotation(
                        node, e0, e, WA[e0.name], WA[e.name]
                    )
            # ^wR_L = ^wR_{A_e} (^{L}R_{A_e})^T, through every measured frame below.
            self.W_link[node] = {
                f: W @ self.rot_in_parent[e.name].T for e in elems for f, W in WA[e.name].items()
            }
        # eqs. (55), (57) generalised: the base rotation from every record and every branch.
        acc = np.zeros((3, 3))
        for f, W in self.W_link[BASE].items():
            acc += np.sum(W[self.valid[f]], axis=0)
        self.R_world_base = project_to_rotation(acc)

    def rotation_fk(self) -> tuple[dict[str, Array], dict[str, Array]]:
        """World rotations predicted by the Step-1 model: (axis frames by joint, measured frames).

        Eqs. (25), (26) for any tree. Typo in the paper: eq. (25) prints ``Rot(z, q_2)`` after
        ``R_2``; joint 2 is prismatic, it is the pan's ``Rot(z, q_3)`` as in eq. (26).
        """
        N = self.N
        link: dict[str, Array] = {BASE: np.broadcast_to(self.R_world_base, (N, 3, 3))}
        axis: dict[str, Array] = {}
        for i, j in enumerate(self.s.joints):
            A = link[j.parent] @ self.rot_in_parent[j.name]
            axis[j.name] = A
            link[j.name] = A @ rot_z(self.q[:, i])[:, :3, :3] if j.type == "revolute" else A
        frames = {f: link[self.s.frame(f).parent] @ self.rot_in_parent[f] for f in self.p.frames}
        return axis, frames

    # ---- Step 2: translations -------------------------------------------------------------------

    def _split(self, joint: str) -> bool:
        """The paper's eq. (11)/(15): a revolute joint carrying several branches gets one axis
        frame, hence one offset, per branch (``l_3L``, ``l_3R``) unless axes are shared."""
        return (
            not self.shared_axes
            and self.s.joint(joint).type == "revolute"
            and len(self.elements[joint]) > 1
        )

    def _key(self, joint: str, frame: str | None = None) -> str:
        """Column block of ``joint``'s unknowns as seen from ``frame`` (default: its first branch)."""
        if not self._split(joint):
            return joint
        elems = self.elements[joint]
        e = next((e for e in elems if frame in e.frames), elems[0])
        return f"{joint}@{e.name}"

    def _columns(self) -> list[tuple[str, int]]:
        cols: list[tuple[str, int]] = []
        for j in self.s.joints:
            width = 2 if j.type == "revolute" else 3
            if self._split(j.name):
                cols += [(f"{j.name}@{e.name}", width) for e in self.elements[j.name]]
            else:
                cols.append((j.name, width))
        cols += [(f, 3) for f in self.p.frames]
        return cols

    def _system(
        self, R_axis: dict[str, Array], R_frame: dict[str, Array]
    ) -> tuple[Array, Array, dict[str, slice]]:
        """Eqs. (61)-(64): ``y = G x`` over every record and measured frame."""
        cols = self._columns()
        where: dict[str, slice] = {}
        k = 0
        for name, width in cols:
            where[name] = slice(k, k + width)
            k += width
        G_rows, y_rows = [], []
        for f in self.p.frames:
            idx = np.flatnonzero(self.valid[f])
            G = np.zeros((len(idx), 3, k))
            for j in self.s.path_to(f):
                ji = self.s.joint_index(j)
                if self.s.joint(j).type == "revolute":
                    G[:, :, where[self._key(j, f)]] = R_axis[j][idx][
                        :, :, :2
                    ]  # ^w R-bar of eq. (62)
                else:
                    # q_i ^w r_{i-1,z} u: a prismatic joint moves along its axis frame's z. Typo in
                    # the paper: eqs. (27), (28) print q_1 r_{0,x} + q_2 r_{1,x}; eq. (58) has r_z.
                    G[:, :, where[j]] = self.q[idx, ji][:, None, None] * R_axis[j][idx]
            G[:, :, where[f]] = R_frame[f][idx]  # ^w R_5 l_5 of eq. (58)
            G_rows.append(G.reshape(-1, k))
            y_rows.append(self.p_meas[f][idx].reshape(-1))
        return np.concatenate(G_rows), np.concatenate(y_rows), where

    def _lstsq(self, G: Array, y: Array, labels: list[str]) -> Array:
        x, _, rank, S = np.linalg.lstsq(G, y, rcond=None)
        if G.shape[1] and (rank < G.shape[1] or S[-1] < RANK_TOL * max(S[0], 1.0)):
            _, _, Vt = np.linalg.svd(G, full_matrices=False)
            worst = labels[int(np.argmax(np.abs(Vt[-1])))]
            raise DegenerateDataError(
                f"the translation system of eq. (64) is rank deficient ({G.shape[0]} equations, "
                f"{G.shape[1]} unknowns, rank {rank}): the data do not fix {worst}"
            )
        return np.asarray(x, dtype=float)

    def step2_translations(self) -> None:
        """Eqs. (58)-(64), then ``|u| = 1`` enforced and the base origin fixed (eq. (67))."""
        R_axis, R_frame = self.rotation_fk()
        G, y, where = self._system(R_axis, R_frame)
        labels = [""] * G.shape[1]
        for name, sl in where.items():
            for c in range(sl.start, sl.stop):
                joint = name.split("@")[0]
                labels[c] = (
                    f"the offset of {name!r}"
                    if name in self.p.frames
                    else (
                        f"the axis line of joint {joint!r}"
                        if self.s.joint(joint).type == "revolute"
                        else f"the direction of prismatic joint {joint!r}"
                    )
                )
        x = self._lstsq(G, y, labels)
        # |u| = 1 (the paper's constraint on ^w r_{0,z}, ^w r_{1,z}); re-solve the rest with u fixed.
        self.u: dict[str, Array] = {}
        for j in self.s.joints:
            if j.type == "prismatic":
                u = x[where[j.name]]
                n = float(np.linalg.norm(u))
                if n < RANK_TOL:
                    raise DegenerateDataError(
                        f"prismatic joint {j.name!r}: its sweep moved no measured frame"
                    )
                self.details.prismatic_norm[j.name] = n
                self.u[j.name] = u / n
        origin = self._base_origin(x, where, R_axis, R_frame)
        fixed = np.zeros(G.shape[1], dtype=bool)
        for name, u in self.u.items():
            fixed[where[name]] = True
            x[where[name]] = u
        y2 = y - G[:, fixed] @ x[fixed] - np.tile(origin, len(y) // 3)
        x[~fixed] = self._lstsq(
            G[:, ~fixed], y2, [lb for lb, f in zip(labels, fixed, strict=True) if not f]
        )
        r = y2 - G[:, ~fixed] @ x[~fixed]
        self.details.translation_rms = float(np.sqrt(np.mean(r**2))) if len(r) else 0.0
        self.x, self.where, self.origin = x, where, origin

    def _base_origin(
        self, x: Array, where: dict[str, slice], R_axis: dict[str, Array], R_frame: dict[str, Array]
    ) -> Array:
        """Eq. (58)'s choice: the base origin on the first revolute axis below the base.

        Follow the first element from the base through prismatic joints; at zero prismatic
        readings the first revolute axis frame sits at ``^wR_A [l_x, l_y, 0]`` (its rotation is
        constant: nothing above it turns). Without a revolute joint, take the frame's origin.
        """
        node = BASE
        while True:
            e = self.elements[node][0]
            if e.is_frame:
                return R_frame[e.name][0] @ x[where[e.name]]
            if self.s.joint(e.name).type == "revolute":
                return R_axis[e.name][0] @ np.array([*x[where[self._key(e.name)]], 0.0])
            node = e.name

    # ---- Step 3: CPC parameters ---------------------------------------------------------------

    def step3_model(self, nominal: CPCModel | None, branch: str | None = None) -> CPCModel:
        """Eqs. (65)-(67): prismatic axis frames, base frame, then every CPC constant.

        With ``shared_axes=False``, ``branch`` (a measured frame) picks which branch's copy of a
        shared joint's offset the model uses: that model is the paper's chain to ``branch``.
        """
        rot = dict(self.rot_in_parent)
        s = self.s
        for j in s.joints:
            if j.type != "prismatic":
                continue
            # eqs. (65), (66): b' = u is the prismatic axis in its child's frame.
            Rb = cpc_rotation(b_from_direction(self.u[j.name]))
            rot[j.name] = rot[j.name] @ Rb.T
            for c in self.elements[j.name]:
                rot[c.name] = Rb @ rot[c.name]
        # The base frame is the axis frame of its first element (the paper's frame 0, eq. (14));
        # its origin is the point chosen in Step 2 (eq. (67), which prints l'_0 for l_0).
        first = self.elements[BASE][0].name
        R_rebase = rot[first]
        R_world_base = self.R_world_base @ R_rebase
        for c in self.elements[BASE]:
            rot[c.name] = R_rebase.T @ rot[c.name]
        joints: dict[str, CPCParams] = {}
        for j in s.joints:
            R = rot[j.name]
            key = self._key(j.name, branch)
            l = np.array([*self.x[self.where[key]], 0.0]) if j.type == "revolute" else np.zeros(3)
            joints[j.name] = CPCParams.from_matrix(homogeneous(R, R @ l))
        frames: dict[str, CPCParams] = {}
        for f in self.p.frames:
            R = rot[f]
            frames[f] = CPCParams.from_matrix(homogeneous(R, R @ self.x[self.where[f]]))
        for name, params in joints.items():
            if params.b[2] < -0.1:  # near-perpendicular axes (b_z ~ 0) may take either sign
                self.details.notes.append(
                    f"joint {name!r}: b_z = {params.b[2]:.3f} < 0: its axis points against its parent's "
                    "(kept: the sign follows the direction in which the reading increases)"
                )
        kept = [f for f in s.frames if f.name in frames]
        for fr in s.frames:
            if fr.name in frames:
                continue
            carried = self._carry_over(fr.name, frames, nominal)
            if carried is None:
                self.details.notes.append(
                    f"frame {fr.name!r} was not measured and "
                    + (
                        "the robot has no nominal geometry"
                        if nominal is None
                        else f"no measured frame shares its link ({fr.parent!r})"
                    )
                    + ": dropped from the identified model"
                )
                continue
            ref, params = carried
            frames[fr.name] = params
            kept.append(fr)
            self.details.notes.append(
                f"frame {fr.name!r} was not measured: kept at its nominal placement relative to {ref!r}"
            )
        kept.sort(key=lambda fr: s.frame_names.index(fr.name))
        structure = s if len(kept) == len(s.frames) else RobotStructure(s.name, s.joints, kept)
        w2b = CPCParams.from_matrix(homogeneous(R_world_base, self.origin))
        return CPCModel(structure, w2b, joints, {f.name: frames[f.name] for f in kept})

    def _carry_over(
        self, name: str, identified: dict[str, CPCParams], nominal: CPCModel | None
    ) -> tuple[str, CPCParams] | None:
        if nominal is None or name not in nominal.frames:
            return None
        parent = self.s.frame(name).parent
        for ref in self.p.frames:
            if self.s.frame(ref).parent == parent and ref in nominal.frames:
                T_ref_frame = inverse(nominal.frames[ref].matrix()) @ nominal.frames[name].matrix()
                return ref, CPCParams.from_matrix(identified[ref].matrix() @ T_ref_frame)
        return None


def count_parameters(
    structure: RobotStructure, frames: tuple[str, ...] | list[str]
) -> dict[str, int]:
    """Independent parameters identified from the poses of ``frames``.

    Each revolute joint's axis is a line (4: direction 2, position 2), each prismatic joint's a
    direction (2), each measured frame's pose at q0 is 6; the base placement adds nothing (it is a
    convention, absorbed by the paths). For the IIS-head: 4*4 + 2*2 + 6*2 = 32. The paper's
    eq. (15) has 34: it gives the right branch its own ``l_3R`` (2 more) on the shared tilt axis.
    """
    used = {j for f in frames for j in structure.path_to(f)}
    n_r = sum(1 for j in structure.joints if j.name in used and j.type == "revolute")
    n_p = sum(1 for j in structure.joints if j.name in used and j.type == "prismatic")
    return {
        "revolute": n_r,
        "prismatic": n_p,
        "frames": len(frames),
        "total": 4 * n_r + 2 * n_p + 6 * len(frames),
    }


def identify_closed_form(
    ms: MeasurementSet, nominal: CPCModel | None = None, *, protocol: Protocol | None = None
) -> tuple[CPCModel, ClosedFormDetails]:
    """Identify every CPC parameter in closed form from one-joint-at-a-time data (sec. 4.2).

    Args:
        ms: Measurements of ``ms.structure`` (``T_world_F`` for the measured frames F).
        nominal: Nominal model of the same robot, used only to carry unmeasured frames (e.g.
            cameras) over relative to a measured frame on the same link; None to drop them.
        protocol: The recognised protocol (default: :func:`recognise_protocol`).

    Returns:
        ``(model, details)``: the identified model (same joints; unmeasured frames kept or
        dropped as ``details.notes`` say) and intermediate results.

    Raises:
        DegenerateDataError: The data cannot determine the robot; the message says why.
    """
    protocol = protocol or recognise_protocol(ms)
    solver = _Solver(ms, protocol)
    solver.step1_rotations()
    solver.step2_translations()
    model = solver.step3_model(nominal)
    return model, solver.details


def identify_paper_branches(
    ms: MeasurementSet, *, protocol: Protocol | None = None
) -> dict[str, CPCModel]:
    """The paper's own model, eq. (15): a joint carrying several branches (the head's tilt) has
    one axis frame *per branch* (``l_3L``, ``l_3R``), i.e. one more axis-line offset (2
    parameters) per extra branch: 34 parameters for the IIS-head instead of 32.

    Steps 1 and 3 are those of :func:`identify_closed_form`; Step 2 (eq. (62)) gives each branch
    its own offset columns for such joints. The result is not one tree, so it is returned as one
    model per measured frame, valid for that frame only (for comparisons; see
    ``cpc2urdf study fig11``).

    Returns:
        ``{frame: model}`` where ``model.fk(q)[frame]`` is the paper's prediction for ``frame``.
    """
    protocol = protocol or recognise_protocol(ms)
    solver = _Solver(ms, protocol, shared_axes=False)
    solver.step1_rotations()
    solver.step2_translations()
    return {f: solver.step3_model(None, branch=f) for f in protocol.frames}


def provenance(ms: MeasurementSet, protocol: Protocol, details: ClosedFormDetails) -> Provenance:
    """The ``provenance`` section of an identified model file."""
    counts = count_parameters(ms.structure, protocol.frames)
    return Provenance(
        method=METHOD,
        measurements=ms.source,
        robot=ms.robot,
        details={
            "reference": "Shih et al. 1992, sec. 4.2 (closed form, generalised to trees)",
            "records": ms.n_records,
            **protocol.summary(),
            "identified_parameters": counts,
            "translation_fit_rms_m": details.translation_rms,
            "beta_rad": {j: v for j, v in details.beta.items() if v},
        },
    )


__all__ = [
    "METHOD",
    "ClosedFormDetails",
    "b_from_direction",
    "count_parameters",
    "identify_closed_form",
    "provenance",
]
