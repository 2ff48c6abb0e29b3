"""Independent references for the gaze solver, shared by its tests and ``cpc2urdf bench gaze``: the
optical axes a solver points computed by Pinocchio (:class:`SolvedAxes`), targets known reachable
on any head from sampled readings, targets no reading fixates, scipy's bounded least squares on the
same residual, and the audit of answers called unreachable.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.transforms import Array
from cpc2urdf.validation.gaze.chain import mid_limits

if TYPE_CHECKING:
    from cpc2urdf.validation.gaze import GazeSolver

# [m]: the audit's random targets are uniform in a cube this far about the head's centre
AUDIT_HALF_WIDTH = 3.0
AUDIT_STARTS = 20  # random postures each audited target is solved again from


class SolvedAxes:
    """The optical axes a solver points (``chain.solve_cameras``), by Pinocchio on a copy of the
    solver's model: the camera frames, and for a rigid pair solved on its cyclopean axis a frame
    added at the midpoint of the centres, z along the sum of the optical axes (it is rigid, so
    placed once at home). Used for targets and the reference, not by the solver."""

    def __init__(self, solver: GazeSolver) -> None:
        import pinocchio as pin

        self.pin = pin
        chain = solver.chain
        model = pin.Model(solver.model)
        fids = [model.getFrameId(c) for c in solver.cameras]
        self.home: Array = mid_limits(solver.lower, solver.upper)
        self.frames: list[int] = []
        for c in chain.solve_cameras.tolist():
            if c < len(fids):
                self.frames.append(fids[c])
                continue
            data = model.createData()
            pin.framesForwardKinematics(model, data, self.home)
            T0, T1 = data.oMf[fids[0]], data.oMf[fids[1]]
            z = T0.rotation[:, 2] + T1.rotation[:, 2]
            z /= np.linalg.norm(z)
            x = T1.translation - T0.translation
            x -= (x @ z) * z
            x /= np.linalg.norm(x)
            M = pin.SE3(
                np.column_stack([x, np.cross(z, x), z]), 0.5 * (T0.translation + T1.translation)
            )
            jid = model.frames[fids[0]].parentJoint
            self.frames.append(
                model.addFrame(
                    pin.Frame(
                        "bench_cyclopean", jid, data.oMi[jid].actInv(M), pin.FrameType.OP_FRAME
                    )
                )
            )
        self.model = model
        self.data = model.createData()
        self.chain = chain

    def axes(self, Q: Array) -> tuple[Array, Array]:
        """Centres (N, S, 3) [m] and unit optical axes (N, S, 3) (world) at readings Q (N, n)."""
        pin, model, data = self.pin, self.model, self.data
        O = np.empty((len(Q), len(self.frames), 3))
        Z = np.empty_like(O)
        for i, q in enumerate(Q):
            pin.framesForwardKinematics(model, data, q)
            for s, f in enumerate(self.frames):
                O[i, s], Z[i, s] = data.oMf[f].translation, data.oMf[f].rotation[:, 2]
        return O, Z

    def residual(self, q: Array, p: Array, jacobian: bool) -> tuple[Array, Array | None]:
        """Per solved axis ``u - e_z`` (``u`` the unit target direction in its frame), shape (3S,),
        and its Jacobian by the readings (3S, n): ``dp_cam = -v + [p_cam]x w`` from the LOCAL
        frame Jacobian, ``du = (I - u u^T) dp_cam / |p_cam|``."""
        pin, model, data = self.pin, self.model, self.data
        if jacobian:
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
        else:
            pin.framesForwardKinematics(model, data, q)
        r, J = [], []
        for f in self.frames:
            pc = data.oMf[f].actInv(p)
            d = float(np.linalg.norm(pc))
            u = pc / d
            r.append(u - np.array([0.0, 0.0, 1.0]))
            if jacobian:
                Jl = pin.getFrameJacobian(model, data, f, pin.LOCAL)
                skew = np.array([[0.0, -pc[2], pc[1]], [pc[2], 0.0, -pc[0]], [-pc[1], pc[0], 0.0]])
                dp = -Jl[:3] + skew @ Jl[3:]
                J.append((np.eye(3) - np.outer(u, u)) @ dp / d)
        return np.concatenate(r), (np.vstack(J) if jacobian else None)

    def pointing_errors(self, q: Array, p: Array) -> Array:
        """Angle [rad] between each solved axis and the direction to target ``p`` at readings
        ``q``, shape (S,)."""
        O, Z = self.axes(q[None, :])
        d = p - O[0]
        return np.arctan2(np.linalg.norm(np.cross(d, Z[0]), axis=1), np.einsum("ij,ij->i", d, Z[0]))


def generic_reachable_targets(axes: SolvedAxes, n: int, seed: int = 0) -> tuple[Array, Array]:
    """``n`` targets (world) [m], shape (n, 3), that readings sampled inside the bounds of the
    solver's unknowns fixate, and those readings (n, n_joints): one solved axis, a point on it
    0.3-3 m ahead; two, the meeting point of axes that meet (to 1e-12 m) 0.15-5 m ahead of both.

    Raises:
        DegenerateDataError: Fewer than ``n`` after 200 rounds (two axes that seldom meet).
    """
    rng = np.random.default_rng(seed)
    chain = axes.chain
    lo, hi = chain.lower, chain.upper
    P: list[Array] = []
    Qs: list[Array] = []
    for _round in range(200):
        if len(P) >= n:
            break
        k = 2 * (n - len(P)) + 16
        U = rng.uniform(lo + 1e-3 * (hi - lo), hi - 1e-3 * (hi - lo), (k, chain.m))
        Q = chain.q_from_u(U)
        O, Z = axes.axes(Q)
        if O.shape[1] == 1:
            pts = O[:, 0] + rng.uniform(0.3, 3.0, k)[:, None] * Z[:, 0]
            ok = np.ones(k, dtype=bool)
        else:
            w = O[:, 0] - O[:, 1]
            b = np.einsum("ij,ij->i", Z[:, 0], Z[:, 1])
            d, e = np.einsum("ij,ij->i", Z[:, 0], w), np.einsum("ij,ij->i", Z[:, 1], w)
            den = np.where(1.0 - b * b > 1e-12, 1.0 - b * b, np.nan)
            s, t = (b * e - d) / den, (e - b * d) / den
            p0, p1 = O[:, 0] + s[:, None] * Z[:, 0], O[:, 1] + t[:, None] * Z[:, 1]
            pts = 0.5 * (p0 + p1)
            with np.errstate(invalid="ignore"):
                ok = (
                    (np.linalg.norm(p0 - p1, axis=1) < 1e-12)
                    & (s > 0.15)
                    & (s < 5.0)
                    & (t > 0.15)
                    & (t < 5.0)
                )
        P += list(pts[ok])
        Qs += list(Q[ok])
    if len(P) < n:
        raise DegenerateDataError(
            f"only {len(P)} of {n} targets found where the solved axes meet in front"
        )
    return np.array(P[:n]), np.array(Qs[:n])


def generic_unreachable_targets(solver: GazeSolver, n: int, seed: int = 0) -> Array:
    """``n`` targets behind the head (world) [m], shape (n, 3): within 15 deg of straight back
    from the head frame's origin (:func:`~cpc2urdf.validation.gaze.reachable.head_frame`), 0.5-3 m
    away. Behind a pan-tilt head whose pan cannot turn round; the benchmark reports how many the
    solver fixates all the same."""
    from cpc2urdf.validation.gaze.reachable import head_frame

    frame = head_frame(solver)
    rng = np.random.default_rng(seed)
    d = rng.uniform(0.5, 3.0, n)
    a = np.radians(15.0) * np.sqrt(rng.random(n))
    phi = rng.uniform(0.0, 2.0 * math.pi, n)
    dirs = np.column_stack([-np.cos(a), np.sin(a) * np.cos(phi), np.sin(a) * np.sin(phi)])
    return frame.to_world(d[:, None] * dirs)


def generic_reference_solver(axes: SolvedAxes) -> Callable[[Array, Array], tuple[Array, int]]:
    """scipy least_squares over the solver's unknowns (its coupling and bounds), on
    :meth:`SolvedAxes.residual`."""
    from scipy.optimize import least_squares

    chain = axes.chain
    A, b = chain.robot_A, chain.robot_b
    lo, hi = chain.lower, chain.upper

    def solve(p: Array, q0: Array) -> tuple[Array, int]:
        def fun(u: Array) -> Array:
            return axes.residual(A @ u + b, p, False)[0]

        def jac(u: Array) -> Array:
            J = axes.residual(A @ u + b, p, True)[1]
            assert J is not None
            return J @ A

        u0 = np.clip(chain.u_from_q(q0), lo + 1e-12, hi - 1e-12)
        res = least_squares(
            fun, u0, jac=jac, bounds=(lo, hi), method="trf", xtol=1e-15, ftol=1e-15, gtol=1e-15
        )
        return A @ res.x + b, int(res.nfev)

    return solve


def audit_targets(axes: SolvedAxes, n: int, seed: int = 0) -> Array:
    """``n`` targets (world) [m], shape (n, 3), uniform in a cube :data:`AUDIT_HALF_WIDTH` about
    the solved cameras' mean centre at home: near and far, in front, beside and behind; most out
    of reach."""
    O, _ = axes.axes(axes.home[None])
    rng = np.random.default_rng(seed)
    return O[0].mean(axis=0) + rng.uniform(-AUDIT_HALF_WIDTH, AUDIT_HALF_WIDTH, (n, 3))


def missed_targets(
    solver: GazeSolver,
    P: Array,
    reachable: NDArray[np.bool_],
    starts: int = AUDIT_STARTS,
    seed: int = 0,
) -> NDArray[np.intp]:
    """The targets of ``P`` (N, 3) answered as not fixated (``reachable`` False) that ``solve``
    fixates from one of ``starts`` random postures (its unknowns uniform in their bounds, as a
    warm start ``q_start``): indices into ``P``. Each is a fixatable target the solver called
    unreachable. A lower bound: a target fixated from none of them may still be fixatable."""
    rng = np.random.default_rng(seed)
    chain = (
        solver.chain
    )  # (its bounds are finite: a joint without limits on a camera's path is refused)
    missed = []
    for i in np.flatnonzero(~np.asarray(reachable)):
        for q in chain.q_from_u(rng.uniform(chain.lower, chain.upper, (starts, chain.m))):
            if solver.solve(P[i], q_start=q).reachable:
                missed.append(i)
                break
    return np.array(missed, dtype=np.intp)


__all__ = [
    "AUDIT_HALF_WIDTH",
    "AUDIT_STARTS",
    "SolvedAxes",
    "audit_targets",
    "generic_reachable_targets",
    "generic_reference_solver",
    "generic_unreachable_targets",
    "missed_targets",
]
