"""Closed-form start for position-only data: circle-point analysis of one-joint-at-a-time sweeps.

Without a nominal model, marker points alone give every joint axis (Stone's circle-point
analysis): while revolute joint j sweeps (the others at ``q0``), a marker on a link j moves turns on
a circle about j's axis; the circle's plane normal is the axis direction (signed by the readings:
``(y_0 - c) x (y_k - c) = r^2 sin(q_k - q_0) u``) and its centre a point on the axis. A prismatic
sweep moves the markers along the joint's direction (signed by the readings). The axes, all known
in world at ``q0``, are chained into a CPC model as the pose closed form does (:mod:`closed_form`,
Step 3): each joint's axis frame has z along the axis, its origin at the foot of the
perpendicular from the parent link's origin (revolute; the gauge ``l_z``) or at that origin
(prismatic), and x as close as possible to the parent's x (the gauge ``beta``); ``E_j =
L_parent(q0)^-1 A_j`` (eq. (3)) and ``L_j = A_j Rot(z, q0_j)`` or ``A_j Trans(z, q0_j)`` (eq. (6)).
The base frame is the world (gauge: ``T_world_base = I``). A frame carrying markers keeps its
nominal placement on its link (or the identity without one); where three of its markers have
known positions its pose is fitted to them (Arun/Kabsch, sec. 3.3). Unknown marker positions are
then the mean of ``T_world_F(q)^-1 y`` over the records.

Each sweep also checks that every marker moves as the link it is declared on does: a marker on a
frame j does not move must stay put, and one on a frame j moves must follow the circle (or line)
the other markers give; when most of the sweep's points (at least two) are off by more than
:data:`WRONG_LINK_SIGMAS` times the noise, the data are refused naming the marker (a marker seen on
the wrong link). A single point off is an outlier, named by the consistency gate after the fit.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.protocol import Protocol, recognise_protocol
from cpc2urdf.model import BASE, CPCModel, CPCParams, RobotStructure
from cpc2urdf.registration import plate_pose_from_points, transforms_from_point_pairs
from cpc2urdf.transforms import Array, inverse

# A marker this close to a joint's axis (relative to the sweep noise) says nothing about it.
MIN_RADIUS_SIGMAS = 20.0  # [-]: circle radius / sigma_p
# A marker is off the motion of its declared link when a sweep point deviates by more than this
# many sigmas (per coordinate, 3-D distance; chi(3) exceeds 7 with probability ~1e-10).
WRONG_LINK_SIGMAS = 7.0  # [-]


@dataclass
class PointStart:
    """What :func:`circle_point_start` returns.

    Attributes:
        model: The CPC model (base = world, axes from the circles and lines).
        positions: Marker name -> position in its frame [m], shape (3,) (given or estimated).
        axes: Joint -> (direction, point on the axis) in world at ``q0`` [-], [m].
        radii: Joint -> marker -> circle radius [m] (revolute joints).
        protocol: The recognised protocol.
        notes: What the start did that a user should know.
    """

    model: CPCModel
    positions: dict[str, Array]
    axes: dict[str, tuple[Array, Array]] = field(default_factory=dict)
    radii: dict[str, dict[str, float]] = field(default_factory=dict)
    protocol: Protocol | None = None
    notes: list[str] = field(default_factory=list)


def fit_circle(Y: Array) -> tuple[Array, Array, float]:
    """Plane normal, centre and radius of 3-D points on a circle (plane by SVD, Kasa fit in it).

    Args:
        Y: Points [m], shape (k, 3), k >= 3, not collinear.

    Returns:
        ``(n, c, r)``: unit normal (sign arbitrary), centre [m], radius [m].
    """
    m = Y.mean(0)
    _, _, Vt = np.linalg.svd(Y - m)
    e1, e2, n = Vt[0], Vt[1], Vt[2]
    u, v = (Y - m) @ e1, (Y - m) @ e2
    # Kasa: u^2 + v^2 = 2 a u + 2 b v + c, linear in (a, b, c).
    A = np.column_stack([2 * u, 2 * v, np.ones_like(u)])
    (a, b, cc), *_ = np.linalg.lstsq(A, u * u + v * v, rcond=None)
    r = float(np.sqrt(max(cc + a * a + b * b, 0.0)))
    return n, m + a * e1 + b * e2, r


def _rotate(u: Array, angle: Array, v: Array) -> Array:
    """``Rot(u, angle) v`` for angles (k,), vector v (3,) -> (k, 3) (Rodrigues)."""
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + np.cross(u, v) * s + np.outer(1 - c, u) * (u @ v)


def _frame_from_axis(z: Array, origin: Array, x_hint: Array) -> Array:
    x = x_hint - (x_hint @ z) * z
    if np.linalg.norm(x) < 1e-6:
        x = np.cross(z, [1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.cross(z, [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, np.cross(z, x), z, origin
    return T


def _joint_motion(kind: str, value: float) -> Array:
    M = np.eye(4)
    if kind == "revolute":
        c, s = np.cos(value), np.sin(value)
        M[:2, :2] = [[c, -s], [s, c]]
    else:
        M[2, 3] = value
    return M


def _systematic(off: np.ndarray) -> bool:
    """A marker is on another link when most of a sweep's points (>= 2) are off, not one (an outlier,
    left to the consistency gate)."""
    return int(off.sum()) >= 2 and int(off.sum()) > len(off) // 2


def _frames_moved_by(s: RobotStructure, joint: str) -> set[str]:
    return {f.name for f in s.frames if joint in s.path_to(f.name)}


def circle_point_start(ms: MeasurementSet, nominal: CPCModel | None, sigma_p: float) -> PointStart:
    """Circle-point analysis of one-joint-at-a-time marker data, chained into a CPC model.

    Args:
        ms: Position-only measurements following the one-joint-at-a-time protocol.
        nominal: Nominal model (frame placements on their links), or None.
        sigma_p: Noise of each measured coordinate [m] (for the wrong-link and radius tests).

    Raises:
        DegenerateDataError: Not the protocol; too few markers for a joint (none off its axis
            seen at q0 and at >= 2 other readings of a revolute joint, >= 1 of a prismatic one);
            a marker that does not move as its declared link does (named).
    """
    s = ms.structure
    protocol = recognise_protocol(ms)
    q0 = protocol.q0
    ref = list(protocol.reference)
    seen_markers = [m for m in ms.marker_points if ms.has_marker(m).any()]
    y0: dict[str, Array] = {}
    for m in seen_markers:
        at_ref = [i for i in ref if ms.has_marker(m)[i]]
        if at_ref:
            y0[m] = ms.marker_points[m][at_ref].mean(0)
    tol_move = WRONG_LINK_SIGMAS * sigma_p * np.sqrt(2.0)  # difference of two noisy points
    link_q0: dict[str, Array] = {BASE: np.eye(4)}
    joints: dict[str, CPCParams] = {}
    axes: dict[str, tuple[Array, Array]] = {}
    radii: dict[str, dict[str, float]] = {}
    for j in s.joints:
        moved_frames = _frames_moved_by(s, j.name)
        sweep = list(protocol.sweeps[j.name])
        theta = ms.q[sweep, s.joint_index(j.name)] - q0[s.joint_index(j.name)]
        # Markers not moved by j must stay put during its sweep.
        for m in seen_markers:
            if m not in y0 or ms.markers[m].frame in moved_frames:
                continue
            ok = ms.has_marker(m)[sweep]
            if ok.any():
                d = np.linalg.norm(ms.marker_points[m][sweep][ok] - y0[m], axis=1)
                if _systematic(d > tol_move):
                    raise DegenerateDataError(
                        f"marker {m!r} is declared on {ms.markers[m].frame!r}, which joint {j.name!r} does not move, "
                        f"but it moves by up to {d.max() * 1e3:.3g} mm while {j.name!r} sweeps (noise "
                        f"{sigma_p * 1e3:.3g} mm): it is on a link that {j.name!r} moves"
                    )
        below = [m for m in seen_markers if m in y0 and ms.markers[m].frame in moved_frames]
        per_marker: dict[str, tuple[Array, Array, float, float]] = {}  # m -> (u, c, r, weight)
        for m in below:
            ok = ms.has_marker(m)[sweep]
            Y = ms.marker_points[m][sweep][ok]
            th = theta[ok]
            if j.type == "revolute":
                if len(Y) < 2:
                    continue
                n, c, r = fit_circle(np.vstack([y0[m], Y]))
                if r < MIN_RADIUS_SIGMAS * sigma_p or not np.isfinite(r):
                    continue
                sgn = np.sum(np.sin(th) * (np.cross(y0[m] - c, Y - c) @ n))
                per_marker[m] = (n if sgn >= 0 else -n, c, r, r * r * len(Y))
            else:
                if len(Y) < 1:
                    continue
                D = Y - y0[m]
                if np.max(np.abs(th)) <= 0:
                    continue
                u = (th @ D) / (th @ th)  # least squares of D = th u
                if np.linalg.norm(u) < 1e-12:
                    continue
                per_marker[m] = (u / np.linalg.norm(u), y0[m], 0.0, float(th @ th))
        if not per_marker:
            need = (
                ">= 2 readings besides q0, off the joint's axis"
                if j.type == "revolute"
                else ">= 1 reading besides q0"
            )
            raise DegenerateDataError(
                f"too few markers for joint {j.name!r}: no marker on a link it moves ({', '.join(sorted(moved_frames))}) "
                f"was seen at q0 and at {need}; put a marker on such a link away from the axis"
            )
        W = np.array([v[3] for v in per_marker.values()])
        u = np.sum([w * v[0] for w, v in zip(W, per_marker.values(), strict=True)], axis=0)
        u /= np.linalg.norm(u)
        centre = (
            np.sum([w * v[1] for w, v in zip(W, per_marker.values(), strict=True)], axis=0)
            / W.sum()
        )
        # Every marker j moves must follow the rotation (translation) of the found axis.
        for m in below:
            ok = ms.has_marker(m)[sweep]
            if not ok.any():
                continue
            Y, th = ms.marker_points[m][sweep][ok], theta[ok]
            if j.type == "revolute":
                pred = centre + _rotate(u, th, y0[m] - centre)
            else:
                pred = y0[m] + np.outer(th, u)
            dev = np.linalg.norm(Y - pred, axis=1)
            if _systematic(dev > tol_move * max(1.0, 3.0 / np.sqrt(len(per_marker)))):
                moved = float(np.linalg.norm(Y - y0[m], axis=1).max())
                raise DegenerateDataError(
                    f"marker {m!r} is declared on {ms.markers[m].frame!r}, which joint {j.name!r} moves, but it does not "
                    f"follow that joint's {'circle' if j.type == 'revolute' else 'line'} (off by up to {dev.max() * 1e3:.3g} mm, "
                    f"moved {moved * 1e3:.3g} mm; noise {sigma_p * 1e3:.3g} mm): it is on another link"
                )
        parent = link_q0[j.parent]
        if j.type == "revolute":
            o = parent[:3, 3]
            foot = centre + ((o - centre) @ u) * u
            A = _frame_from_axis(u, foot, parent[:3, 0])
            radii[j.name] = {m: v[2] for m, v in per_marker.items()}
        else:
            A = _frame_from_axis(u, parent[:3, 3], parent[:3, 0])
        axes[j.name] = (u, centre)
        joints[j.name] = CPCParams.from_matrix(inverse(parent) @ A)
        link_q0[j.name] = A @ _joint_motion(j.type, float(q0[s.joint_index(j.name)]))
    frames: dict[str, CPCParams] = {}
    notes: list[str] = []
    for f in s.frames:
        E = (
            nominal.frames[f.name].matrix()
            if nominal is not None and f.name in nominal.frames
            else np.eye(4)
        )
        frames[f.name] = CPCParams.from_matrix(E)
    model = CPCModel(s, CPCParams(), joints, frames)
    model, positions = place_markers(model, ms, ref)
    notes.append("start: circle-point analysis of each joint's marker sweep (position-only data)")
    return PointStart(model, positions, axes, radii, protocol, notes)


def place_markers(
    model: CPCModel, ms: MeasurementSet, at: list[int] | None = None
) -> tuple[CPCModel, dict[str, Array]]:
    """Frames with >= 3 markers of known position fitted to them; unknown marker positions estimated.

    Args:
        model: The model whose joints are known (frames at their start placement).
        ms: The measurements.
        at: Records used to fit frames to known markers (default: all).

    Returns:
        ``(model, positions)``: the model with fitted frame placements, and marker name ->
        position in its frame [m].
    """
    s = model.structure
    at = list(range(ms.n_records)) if at is None else at
    seen = [m for m in ms.marker_points if ms.has_marker(m).any()]
    frames: dict[str, CPCParams] = {}
    for f in dict.fromkeys(ms.markers[m].frame for m in seen):
        known = [m for m in seen if ms.markers[m].frame == f and ms.markers[m].known]
        rows = [i for i in at if all(ms.has_marker(m)[i] for m in known)]
        if len(known) >= 3 and rows:
            parent = s.frame(f).parent
            i = rows[0]
            link = (
                model.T_world_base()
                if parent == BASE
                else model.link_poses(ms.q[i])[1][0, s.joint_index(parent)]
            )
            layout = np.array([ms.markers[m].position for m in known], dtype=float)
            T_world_f = plate_pose_from_points(
                layout, np.array([ms.marker_points[m][i] for m in known]), what=f"frame {f}"
            )
            frames[f] = CPCParams.from_matrix(inverse(link) @ T_world_f)
    model = model.with_params(frames=frames) if frames else model
    T = model.fk(ms.q, list(dict.fromkeys(ms.markers[m].frame for m in seen)))
    positions: dict[str, Array] = {}
    for m in seen:
        mk = ms.markers[m]
        if mk.position is not None:
            positions[m] = np.array(mk.position, dtype=float)
            continue
        ok = ms.has_marker(m)
        Tf = T[mk.frame][ok]
        local = np.einsum("nji,nj->ni", Tf[:, :3, :3], ms.marker_points[m][ok] - Tf[:, :3, 3])
        positions[m] = local.mean(0)
    return model, positions


def nominal_point_start(
    nominal: CPCModel, ms: MeasurementSet, iterations: int = 100
) -> tuple[CPCModel, dict[str, Array]]:
    """Start for marker data at arbitrary configurations: the nominal model placed in world.

    The nominal model does not know where the robot stands in the tracker's world nor (for
    unknown markers) where the markers are on their links: alternate a rigid fit of
    ``T_world_base`` to the measured points (Arun/Kabsch, sec. 3.3) with the markers' positions
    given that placement (each a mean over the records), from markers at their frames' origins.

    Args:
        nominal: The nominal model.
        ms: Position-only measurements (any configurations).
        iterations: Alternations (each is a closed-form step; they converge geometrically).
    """
    seen = [m for m in ms.marker_points if ms.has_marker(m).any()]
    frames = list(dict.fromkeys(ms.markers[m].frame for m in seen))
    T_world = nominal.fk(ms.q, frames)
    T_base: dict[str, Array] = {
        f: np.asarray(np.linalg.solve(nominal.T_world_base(), T_world[f]), dtype=np.float64)
        for f in frames
    }  # T_base_F(q)
    pos = {
        m: np.array(ms.markers[m].position, dtype=float) if ms.markers[m].known else np.zeros(3)
        for m in seen
    }
    G = np.eye(4)
    for _ in range(iterations):
        a, b = [], []
        for m in seen:
            ok = ms.has_marker(m)
            Tf = T_base[ms.markers[m].frame][ok]
            a.append(Tf[:, :3, :3] @ pos[m] + Tf[:, :3, 3])
            b.append(ms.marker_points[m][ok])
        G = transforms_from_point_pairs(
            np.concatenate(a), np.concatenate(b), what="marker points"
        )  # eqs. (18)-(22)
        for m in seen:
            if ms.markers[m].known:
                continue
            ok = ms.has_marker(m)
            Tw = G @ T_base[ms.markers[m].frame][ok]
            pos[m] = np.einsum(
                "nji,nj->ni", Tw[:, :3, :3], ms.marker_points[m][ok] - Tw[:, :3, 3]
            ).mean(0)
    model = nominal.with_params(world_to_base=CPCParams.from_matrix(G @ nominal.T_world_base()))
    return model, pos


def marker_sigma(metadata: Mapping[str, object]) -> tuple[float, bool]:
    """``(sigma_p, known)`` from a measurement set's ``noise`` section (``sigma_p_m``), else the default."""
    from cpc2urdf.identification.kinematics.points.point_problem import DEFAULT_SIGMA_P

    noise = metadata.get("noise") if isinstance(metadata, Mapping) else None
    if isinstance(noise, Mapping):
        sp = noise.get("sigma_p_m")
        if isinstance(sp, (int, float)) and sp > 0:
            return float(sp), True
    return DEFAULT_SIGMA_P, False


__all__ = [
    "MIN_RADIUS_SIGMAS",
    "WRONG_LINK_SIGMAS",
    "PointStart",
    "circle_point_start",
    "fit_circle",
    "marker_sigma",
    "nominal_point_start",
    "place_markers",
]
