"""Simulated stage-1 experiments (Shih et al. sec. 4.1 protocol, sec. 6 / Fig. 10 noise).

A "true" robot is the nominal model plus seeded random geometric errors (a real head is not its
drawing). It is placed in front of a stereo rig (world = the rig's left camera frame) so that both
cameras see every circle of both plates over the calibration range (no plate hiding another,
:func:`clear_placement`), and measured with the one-joint-at-a-time
protocol: one record at ``q0`` (the middle of every joint's calibration range), then, for each
joint in turn, ``M`` values evenly spread over its calibration range with the other joints at
``q0`` (``n M + 1`` records; 6M+1 for the IIS-head). Every record measures every plate.

In memory::

    from cpc2urdf.identification.simulation.simulate import simulate_experiment
    truth, measured, heldout = simulate_experiment("iis_head", seed=1, M=9, noise="fig10",
                                                   sigma_t=0.5e-3, sigma_r=np.radians(0.5))

``truth`` is a :class:`~cpc2urdf.model.CPCModel`; ``measured`` and ``heldout`` are
:class:`~cpc2urdf.measurements.MeasurementSet` (held-out records carry the *true* poses).
``cpc2urdf simulate`` writes the same three things as files.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.identification.simulation.noise import fig10_noise, random_rotations, stereo_noise
from cpc2urdf.identification.vision.render import PlateDesign, occluded_circles, robot_plate_designs
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.measurements import MeasurementSet
from cpc2urdf.model import CPCModel, CPCParams, RobotStructure
from cpc2urdf.progress import progress
from cpc2urdf.spec import RobotSpec
from cpc2urdf.transforms import homogeneous

Array = NDArray[np.float64]

NOISE_MODELS = ("fig10", "stereo", "none")
# Defaults (SI). The paper's Fig. 11 uses one sigma_O for both: sigma_O mm and sigma_O degrees.
DEFAULT_M = 9  # sec. 6: "we choose to use nine measurements for each joint"
DEFAULT_SIGMA_T = 0.5e-3  # [m]: the paper's rig accuracy (sec. 6)
DEFAULT_SIGMA_R = math.radians(0.5)  # [rad]
DEFAULT_PIXEL_SIGMA = 0.15  # [px]: ~0.5 mm per circle centre with the default rig (docs/measurements.md)
DEFAULT_GEOMETRY_ERROR_T = 1e-3  # [m], per CPC offset component
DEFAULT_GEOMETRY_ERROR_R = math.radians(0.5)  # [rad], about a random axis
DEFAULT_HELDOUT = 50
VIEW_MARGIN_PX = 20.0  # [px]: circles must stay this far inside both images
OCCLUDED_VIEWS_MAX = 0.05  # [-]: share of (configuration, plate) views with a hidden circle tolerated
MAX_VIEW_ANGLE = math.radians(75.0)  # [rad]: plate normal vs line of sight to either camera
OCCLUSION_MARGIN_PX = 3.0  # [px]: a circle's image must stay this far from any other plate's image
# [px]: the placement search asks for more clearance on the nominal robot, so that the true robot
# (nominal + ~1 mm / 0.5 deg errors, a few px at 1.5 m) still keeps OCCLUSION_MARGIN_PX.
PLACEMENT_MARGIN_PX = 10.0


class Experiment(NamedTuple):
    """What :func:`simulate_experiment` returns (unpacks as ``truth, measured, heldout``)."""

    truth: CPCModel
    measured: MeasurementSet
    heldout: MeasurementSet


# ---- the true robot -------------------------------------------------------------------------------


def perturb_params(p: CPCParams, rng: np.random.Generator, sigma_t: float, sigma_r: float) -> CPCParams:
    """``p`` with its rotation pre-multiplied by a random small rotation and ``l`` offset.

    Args:
        p: Nominal CPC constants.
        rng: Random generator.
        sigma_t: Standard deviation of each component of the offset added to ``l`` [m].
        sigma_r: Standard deviation of the rotation angle about a random axis [rad]; this tilts
            the axis direction ``b`` and changes ``beta``.
    """
    R = random_rotations(rng, sigma_r, 1)[0] @ p.rotation()
    l = np.asarray(p.l) + rng.normal(0.0, sigma_t, size=3)
    return CPCParams.from_matrix(homogeneous(R, R @ l))


def perturbed_model(nominal: CPCModel, rng: np.random.Generator, sigma_t: float, sigma_r: float) -> CPCModel:
    """A "true" robot: every joint's and frame's CPC constants and ``world_to_base`` perturbed."""
    s = nominal.structure
    joints = {n: perturb_params(nominal.joints[n], rng, sigma_t, sigma_r) for n in s.joint_names}
    frames = {n: perturb_params(nominal.frames[n], rng, sigma_t, sigma_r) for n in s.frame_names}
    w2b = perturb_params(nominal.world_to_base, rng, sigma_t, sigma_r)
    return nominal.with_params(world_to_base=w2b, joints=joints, frames=frames)


# ---- configurations -------------------------------------------------------------------------------


def calibration_ranges(
    structure: RobotStructure, overrides: Mapping[str, tuple[float, float]] | None = None
) -> Array:
    """Per joint ``[lo, hi]`` [m]/[rad], shape (n, 2): ``overrides``, else the spec's
    ``calibration_range``, else the middle half of the joint limits."""
    out = np.empty((structure.n_joints, 2))
    overrides = dict(overrides or {})
    for name in overrides:
        structure.joint(name)
    for i, j in enumerate(structure.joints):
        if j.name in overrides:
            lo, hi = (float(v) for v in overrides[j.name])
            if not (j.lower - 1e-12 <= lo <= hi <= j.upper + 1e-12):
                raise ConfigurationError(
                    f"joint {j.name!r}: calibration range [{lo:.6g}, {hi:.6g}] must lie within the "
                    f"limits [{j.lower:.6g}, {j.upper:.6g}]"
                )
            out[i] = lo, hi
        elif j.calibration_range is not None:
            out[i] = j.calibration_range
        else:
            mid, half = (j.lower + j.upper) / 2, (j.upper - j.lower) / 4
            out[i] = mid - half, mid + half
    return out


def protocol_configurations(ranges: ArrayLike, M: int, joint_names: Sequence[str]) -> tuple[Array, list[str]]:
    """The one-joint-at-a-time protocol of sec. 4.1.

    Args:
        ranges: Per joint ``[lo, hi]``, shape (n, 2).
        M: Values per joint (>= 2), evenly spaced over its range, ends included.
        joint_names: Names for the labels, length n.

    Returns:
        ``(q, labels)``: q of shape (n M + 1, n), first ``q0`` (the middle of every range), then
        joint 0's M values, joint 1's, ...; labels ``"q0"``, ``"<joint> k/M"``.
    """
    r = np.asarray(ranges, dtype=float)
    if M < 2:
        raise ConfigurationError(f"M must be at least 2 values per joint, got {M}")
    q0 = r.mean(axis=1)
    qs, labels = [q0], ["q0"]
    for i, name in enumerate(joint_names):
        for k, v in enumerate(np.linspace(r[i, 0], r[i, 1], M)):
            q = q0.copy()
            q[i] = v
            qs.append(q)
            labels.append(f"{name} {k + 1}/{M}")
    return np.array(qs), labels


def random_configurations(ranges: ArrayLike, n: int, rng: np.random.Generator) -> Array:
    """``n`` configurations uniform in the box ``ranges`` (shape (n_joints, 2)), shape (n, n_joints)."""
    r = np.asarray(ranges, dtype=float)
    return r[:, 0] + (r[:, 1] - r[:, 0]) * rng.random((n, r.shape[0]))


# ---- placing the robot in front of the rig -------------------------------------------------------------


def measured_frames(structure: RobotStructure) -> list[str]:
    """The frames stage 1 measures: those of kind ``"plate"``."""
    return [f.name for f in structure.frames if f.kind == "plate"]


def _frame_points(structure: RobotStructure, name: str) -> Array:
    layout = structure.frame(name).layout
    return np.zeros((1, 3)) if layout is None else np.array(layout, dtype=float)


def place_in_front_of_rig(
    model: CPCModel, rig: StereoRig, q: ArrayLike, frames: Sequence[str], *, up_base: ArrayLike | None = None
) -> CPCParams:
    """A ``world_to_base`` that shows the plates to the rig face-on, centred and ~at its distance.

    The rig looks along the mean plate normal (so the plates' +z faces the cameras), its image
    "down" follows the robot's down (``-up_base``), and the centre of the plates' bounding box
    sits at the point where the rig's optical axes meet.

    Args:
        model: The robot (its own ``world_to_base`` is ignored).
        rig: The measuring rig.
        q: Configurations the plates must be seen in, shape (N, n).
        frames: The plates.
        up_base: The robot's up direction in base; default: the axis of the first revolute joint
            at the middle configuration (the pan axis of a head), else base z.

    Returns:
        CPC constants of ``T_world_base``.
    """
    at_base = model.with_params(world_to_base=CPCParams())
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    fk = at_base.fk(qq, frames)
    P = np.concatenate([
        (np.einsum("nij,kj->nki", fk[f][:, :3, :3], _frame_points(model.structure, f)) + fk[f][:, None, :3, 3])
        .reshape(-1, 3) for f in frames
    ])
    n_mean, up = _mean_normal_and_up(at_base, qq, frames)
    view_b = -n_mean  # rig looks against the plate normals
    if up_base is not None:
        up = np.asarray(up_base, dtype=float)
    down_b = -(up - (up @ view_b) * view_b)
    if np.linalg.norm(down_b) < 1e-6:  # looking straight along "up": any image orientation
        down_b = np.cross(view_b, [1.0, 0.0, 0.0] if abs(view_b[0]) < 0.9 else [0.0, 1.0, 0.0])
    down_b /= np.linalg.norm(down_b)
    R_base_view = np.column_stack([np.cross(down_b, view_b), down_b, view_b])
    # The rig's own viewing frame: z = mean optical axis, y = mean image down, origin = fixation.
    T_wl, T_wr = rig.T_world_camera("left"), rig.T_world_camera("right")
    z_w = T_wl[:3, 2] + T_wr[:3, 2]
    z_w /= np.linalg.norm(z_w)
    y_w = T_wl[:3, 1] + T_wr[:3, 1]
    y_w -= (y_w @ z_w) * z_w
    y_w /= np.linalg.norm(y_w)
    R_world_view = np.column_stack([np.cross(y_w, z_w), y_w, z_w])
    fixation_w = _closest_point_of_two_lines(T_wl[:3, 3], T_wl[:3, 2], T_wr[:3, 3], T_wr[:3, 2])
    R_wb = R_world_view @ R_base_view.T
    centre_b = (P.min(axis=0) + P.max(axis=0)) / 2
    t_wb = fixation_w - R_wb @ centre_b
    return CPCParams.from_matrix(homogeneous(R_wb, t_wb))


def _mean_normal_and_up(at_base: CPCModel, q: Array, frames: Sequence[str]) -> tuple[Array, Array]:
    """Unit mean plate normal over ``q`` (N, n) and the robot's up direction, both in base.

    Up is the axis of the first revolute joint at the middle configuration (the pan axis of a
    head), else base z; ``at_base`` is the robot with ``world_to_base`` = identity.
    """
    fk = at_base.fk(q, frames)
    n_mean = np.concatenate([fk[f][:, :3, 2] for f in frames]).mean(axis=0)
    if np.linalg.norm(n_mean) < 1e-6:
        n_mean = np.array([0.0, 0.0, 1.0])
    up = np.array([0.0, 0.0, 1.0])
    revolute = [i for i, j in enumerate(at_base.structure.joints) if j.type == "revolute"]
    if revolute:
        _, axes = at_base.joint_axes_world(q.mean(axis=0))
        up = axes[0, revolute[0]]
    return n_mean / np.linalg.norm(n_mean), up


def _closest_point_of_two_lines(a: Array, u: Array, b: Array, v: Array) -> Array:
    # Midpoint of the common perpendicular of lines a + s u and b + t v.
    w = a - b
    uu, uv, vv, uw, vw = u @ u, u @ v, v @ v, u @ w, v @ w
    den = uu * vv - uv * uv
    if abs(den) < 1e-12:  # parallel optical axes: look 1.5 m ahead of the left camera
        return a + 1.5 * u
    s = (uv * vw - vv * uw) / den
    t = (uu * vw - uv * uw) / den
    return ((a + s * u) + (b + t * v)) / 2


@dataclass
class ViewReport:
    """How well the rig sees the plates over a set of configurations.

    Attributes:
        ok: Every circle of every plate seen by both cameras, face-on enough, hidden by no other
            plate, in every config.
        problems: One line per (configuration, plate) that fails: out of view or too oblique
            first, then hidden circles.
        min_margin_px: Smallest distance of a circle centre from an image border [px].
        max_view_angle: Largest angle between a plate normal and a line of sight [rad].
        distance_range: Min and max distance of plate origins from the left camera [m].
        unseen: Number of (configuration, plate) pairs outside an image or too oblique.
        hidden: Number of (configuration, plate, camera, circle) sightings blocked by another
            plate or by the plate's own back (:func:`~cpc2urdf.identification.vision.render.
            occluded_circles`).
        hidden_per_config: Those sightings per configuration, shape (N,).
        unseen_per_config: Plates outside an image or too oblique, per configuration, shape (N,).
    """

    ok: bool
    problems: list[str]
    min_margin_px: float
    max_view_angle: float
    distance_range: tuple[float, float]
    unseen: int = 0
    hidden: int = 0
    hidden_per_config: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    unseen_per_config: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


def check_view(
    model: CPCModel,
    rig: StereoRig,
    q: ArrayLike,
    frames: Sequence[str],
    labels: Sequence[str],
    *,
    margin_px: float = VIEW_MARGIN_PX,
    max_angle: float = MAX_VIEW_ANGLE,
    occlusion_margin_px: float | None = OCCLUSION_MARGIN_PX,
    designs: Sequence[PlateDesign] | None = None,
) -> ViewReport:
    """Check that both rig cameras see every circle of every plate in every configuration.

    A (configuration, plate) fails when a circle centre is less than ``margin_px`` inside an
    image, when a line of sight is more than ``max_angle`` off the plate normal, or when a camera
    cannot see a circle because another plate is in the way or the plate shows its back (a 3-D
    ray test against the plate rectangles, with ``occlusion_margin_px`` of clearance).

    Args:
        model: The robot, placed in the rig's world.
        rig: The measuring rig.
        q: Configurations, shape (N, n).
        frames: The plates.
        labels: One label per configuration (for the problem lines).
        margin_px: Required distance of circle centres from the image borders [px].
        max_angle: Largest angle between plate normal and line of sight [rad].
        occlusion_margin_px: Required clearance between a circle's image and any other plate's
            image [px]; None skips the occlusion test.
        designs: Plate outlines for the occlusion test (default: :func:`~cpc2urdf.
            identification.render.robot_plate_designs`, the layout's bounding box + 10 mm).
    """
    qq = np.atleast_2d(np.asarray(q, dtype=float))
    fk = model.fk(qq, frames)
    w, h = rig.image_size
    problems: list[str] = []
    hidden_problems: list[str] = []  # listed after the out-of-view ones
    min_margin, max_ang, dists = math.inf, 0.0, []
    cameras = [("left", rig.T_world_camera("left")[:3, 3], float(rig.K1[0, 0])),
               ("right", rig.T_world_camera("right")[:3, 3], float(rig.K2[0, 0]))]
    occluded: dict[str, list[NDArray[np.bool_]]] = {}
    if occlusion_margin_px is not None:
        by_name = {d.name: d for d in (robot_plate_designs(model.structure.frames) if designs is None else designs)}
        plates = [(by_name[f], fk[f]) for f in frames if f in by_name]
        for _, centre, focal in cameras:
            for f, mask in occluded_circles(centre, focal, plates, margin_px=occlusion_margin_px).items():
                occluded.setdefault(f, []).append(mask)
    unseen = 0
    per_config = np.zeros(len(qq), dtype=np.int64)
    unseen_per_config = np.zeros(len(qq), dtype=np.int64)
    for f in frames:
        T = fk[f]
        pts = np.einsum("nij,kj->nki", T[:, :3, :3], _frame_points(model.structure, f)) + T[:, None, :3, 3]
        seen = rig.in_view(pts, margin_px=margin_px)
        uv1, uv2 = rig.project(pts)
        for uv in (uv1, uv2):
            m = np.minimum.reduce([uv[..., 0], w - 1 - uv[..., 0], uv[..., 1], h - 1 - uv[..., 1]])
            min_margin = min(min_margin, float(np.nanmin(m)))
        ang = np.zeros(len(qq))
        for _, c, _ in cameras:
            los = c - T[:, :3, 3]
            los /= np.linalg.norm(los, axis=1, keepdims=True)
            ang = np.maximum(ang, np.arccos(np.clip(np.einsum("ni,ni->n", los, T[:, :3, 2]), -1, 1)))
        max_ang = max(max_ang, float(ang.max()))
        dists.append(np.linalg.norm(T[:, :3, 3], axis=1))
        blocked = occluded.get(f, [np.zeros(seen.shape, dtype=bool)] * 2)
        per_config += blocked[0].sum(axis=1) + blocked[1].sum(axis=1)
        bad_view = ~seen.all(axis=1) | (ang > max_angle)
        unseen += int(bad_view.sum())
        unseen_per_config += bad_view
        for i in np.flatnonzero(bad_view | blocked[0].any(axis=1) | blocked[1].any(axis=1)):
            if not seen[i].all():
                why = f"{int((~seen[i]).sum())} of {seen.shape[1]} circles outside an image (margin {margin_px:g} px)"
            elif ang[i] > max_angle:
                why = f"seen at {math.degrees(ang[i]):.0f} deg from face-on (limit {math.degrees(max_angle):.0f})"
            else:
                why = "; ".join(
                    f"{int(b[i].sum())} of {b.shape[1]} circles hidden from the {cam} camera by another plate "
                    f"or its own back (clearance {occlusion_margin_px:g} px)"
                    for (cam, _, _), b in zip(cameras, blocked, strict=True) if b[i].any()
                )
                hidden_problems.append(f"{f} at {labels[int(i)]}: {why}")
                continue
            problems.append(f"{f} at {labels[int(i)]}: {why}")
    problems += hidden_problems
    d = np.concatenate(dists)
    return ViewReport(not problems, problems, min_margin, max_ang, (float(d.min()), float(d.max())), unseen,
                      int(per_config.sum()), per_config, unseen_per_config)


_PLACEMENTS: dict[bytes, CPCParams] = {}


def _memo_clear_placement(
    model: CPCModel, rig: StereoRig, q: NDArray[np.float64], frames: Sequence[str], q_sample: NDArray[np.float64]
) -> CPCParams:
    """:func:`clear_placement`, remembered per (robot geometry, rig, configurations): the search
    takes about a second and studies simulate hundreds of experiments with the same inputs."""
    parts = [np.asarray(v, dtype=float).tobytes() for v in (rig.K1, rig.D1, rig.K2, rig.D2, rig.R, rig.T, rig.image_size, q, q_sample)]
    parts += [model.joints[n].to_vector().tobytes() for n in model.structure.joint_names]
    parts += [model.frames[n].to_vector().tobytes() for n in model.structure.frame_names]
    parts += [repr((model.structure.joint_names, [(f.name, f.layout) for f in model.structure.frames], tuple(frames))).encode()]
    key = b"|".join(parts)
    if key not in _PLACEMENTS:
        if len(_PLACEMENTS) > 64:
            _PLACEMENTS.clear()
        _PLACEMENTS[key] = clear_placement(model, rig, q, frames, q_sample=q_sample)
    return _PLACEMENTS[key]


def clear_placement(
    model: CPCModel,
    rig: StereoRig,
    q: ArrayLike,
    frames: Sequence[str],
    *,
    q_sample: ArrayLike | None = None,
    designs: Sequence[PlateDesign] | None = None,
    occlusion_margin_px: float = PLACEMENT_MARGIN_PX,
) -> CPCParams:
    """A ``world_to_base`` from which both cameras see every circle of every plate over ``q``.

    Starts from the face-on placement of :func:`place_in_front_of_rig`, which for the IIS-head
    lets one plate hide part of the other (the plates sit ~0.13 m apart along their normals),
    then tries, in a fixed order, the image rolled by +-90 deg and the robot turned by up to
    40 deg (steps of 10 deg) about the rig's x and y axes through the plates' centre. Only
    placements that keep every circle of ``q`` and ``q_sample`` inside both images and at most
    ``MAX_VIEW_ANGLE`` off face-on count; among them it returns the one with the fewest hidden
    circles (:func:`check_view`) over ``q``, then over ``q_sample``, then the most face-on, and
    stops at the first unturned one with none hidden. Deterministic: depends on the robot, the rig
    and the configurations only.

    Args:
        model: The robot (its own ``world_to_base`` is ignored).
        rig: The measuring rig.
        q: Configurations in which every circle must be seen (the protocol), shape (N, n).
        frames: The plates.
        q_sample: Further configurations in which as few circles as possible should be hidden
            (e.g. a sample of the calibration ranges), shape (M, n).
        designs: Plate outlines for the occlusion test (default: the robot's plate designs).
        occlusion_margin_px: Clearance between a circle's image and other plates' images [px].

    Returns:
        CPC constants of ``T_world_base``; if no candidate keeps the plates in view, the face-on
        placement (so that :func:`check_view` can explain what is out of view).
    """
    from scipy.spatial.transform import Rotation

    qq = np.atleast_2d(np.asarray(q, dtype=float))
    n_q = len(qq)
    if q_sample is not None:
        qq = np.vstack([qq, np.atleast_2d(np.asarray(q_sample, dtype=float))])
    n, up0 = _mean_normal_and_up(model.with_params(world_to_base=CPCParams()), qq, frames)
    u = up0 - (up0 @ n) * n
    ups: list[Array | None] = [None]
    if np.linalg.norm(u) > 1e-6:
        u /= np.linalg.norm(u)
        ups += [np.cross(n, u), -np.cross(n, u)]  # image rolled by -+90 deg
    labels = [str(i) for i in range(len(qq))]
    face_on: CPCParams | None = None
    best: tuple[tuple[int, int, float], CPCParams] | None = None
    for up in ups:
        T0 = place_in_front_of_rig(model, rig, qq, frames, up_base=up).matrix()
        F = model.with_params(world_to_base=CPCParams.from_matrix(T0)).fk(qq, frames)
        c = np.concatenate([F[f][:, :3, 3] for f in frames])
        fix = (c.min(axis=0) + c.max(axis=0)) / 2
        for axis in ("x", "y"):
            for ang in (0, -10, 10, -20, 20, -30, 30, -40, 40):
                if ang == 0 and axis == "y":
                    continue
                R = Rotation.from_euler(axis, ang, degrees=True).as_matrix()
                w2b = CPCParams.from_matrix(homogeneous(R, fix - R @ fix) @ T0)
                face_on = face_on or w2b
                view = check_view(model.with_params(world_to_base=w2b), rig, qq, frames, labels,
                                  occlusion_margin_px=occlusion_margin_px, designs=designs)
                if view.unseen:
                    continue
                h = view.hidden_per_config
                key = (int(h[:n_q].sum()), int(h[n_q:].sum()), view.max_view_angle)
                if best is None or key < best[0]:
                    best = (key, w2b)
                if view.hidden == 0 and ang == 0:
                    return w2b
    assert face_on is not None
    return face_on if best is None else best[1]


def visible_heldout(
    truth: CPCModel,
    rig: StereoRig,
    ranges: ArrayLike,
    n: int,
    frames: Sequence[str],
    rng: np.random.Generator,
    *,
    max_rounds: int = 20,
) -> tuple[Array, int]:
    """``n`` random configurations in ``ranges`` (n_joints, 2) in which the rig sees every circle.

    Draws ``n`` configurations uniformly, then redraws (from ``rng``, in order) those in which
    :func:`check_view` finds a circle hidden by a plate, outside an image or seen too obliquely --
    a real validation set holds only poses the rig can measure -- for at most ``max_rounds``
    rounds; whatever is still unmeasurable then is left for :func:`check_view` to report.

    Returns:
        ``(q, redrawn)``: configurations of shape (n, n_joints) and how many draws were replaced.
    """
    q = random_configurations(ranges, n, rng)
    redrawn = 0
    for _ in range(max_rounds):
        if n == 0:
            break
        view = check_view(truth, rig, q, frames, [str(i) for i in range(n)])
        bad = np.flatnonzero((view.hidden_per_config > 0) | (view.unseen_per_config > 0))
        if bad.size == 0:
            break
        q[bad] = random_configurations(ranges, bad.size, rng)
        redrawn += int(bad.size)
    return q, redrawn


# ---- measuring ----------------------------------------------------------------------------------------


def measure_poses(
    model: CPCModel,
    q: ArrayLike,
    frames: Sequence[str],
    rng: np.random.Generator,
    *,
    noise: str = "fig10",
    sigma_t: float = DEFAULT_SIGMA_T,
    sigma_r: float = DEFAULT_SIGMA_R,
    rig: StereoRig | None = None,
    pixel_sigma: float = DEFAULT_PIXEL_SIGMA,
) -> tuple[dict[str, Array], dict[str, Array]]:
    """Noisy ``T_world_<frame>`` of ``model`` at ``q`` (N, n) under a noise model.

    Args:
        model: The true robot (placed in the rig's world).
        q: Configurations, shape (N, n).
        frames: Frames to measure (plates).
        rng: Random generator.
        noise: ``"fig10"`` (sigma_t, sigma_r), ``"stereo"`` (pixel_sigma through ``rig``) or
            ``"none"``.
        sigma_t: Fig. 10 translation noise per entry [m].
        sigma_r: Fig. 10 rotation noise angle [rad].
        rig: The stereo rig (``"stereo"`` only).
        pixel_sigma: Pixel noise per coordinate [px] (``"stereo"`` only).

    Returns:
        ``(poses, points)``: frame -> (N, 4, 4); for the stereo model also frame -> (N, K, 3)
        triangulated circle centres.
    """
    true = model.fk(np.atleast_2d(np.asarray(q, dtype=float)), frames)
    poses: dict[str, Array] = {}
    points: dict[str, Array] = {}
    for f in frames:
        if noise == "none":
            poses[f] = true[f]
        elif noise == "fig10":
            poses[f] = fig10_noise(true[f], sigma_t, sigma_r, rng)
        elif noise == "stereo":
            layout = model.structure.frame(f).layout
            if rig is None or layout is None:
                raise ConfigurationError(f"stereo noise needs a rig and a circle layout for {f!r}")
            poses[f], points[f] = stereo_noise(true[f], np.array(layout), rig, pixel_sigma, rng)
        else:
            raise ConfigurationError(f"noise model must be one of {NOISE_MODELS}, got {noise!r}")
    return poses, points


# ---- the whole experiment ---------------------------------------------------------------------------


def _as_spec(robot: str | Path | RobotSpec | CPCModel) -> tuple[RobotSpec, str]:
    if isinstance(robot, RobotSpec):
        return robot, robot.source
    if isinstance(robot, CPCModel):
        return RobotSpec(robot.structure, robot, "<memory>"), robot.structure.name
    from cpc2urdf.robot_ref import load_robot

    return load_robot(robot), str(robot)


def simulate_experiment(
    robot: str | Path | RobotSpec | CPCModel = "iis_head",
    *,
    seed: int = 0,
    M: int = DEFAULT_M,
    noise: str = "fig10",
    sigma_t: float = DEFAULT_SIGMA_T,
    sigma_r: float = DEFAULT_SIGMA_R,
    pixel_sigma: float = DEFAULT_PIXEL_SIGMA,
    geometry_error_t: float = DEFAULT_GEOMETRY_ERROR_T,
    geometry_error_r: float = DEFAULT_GEOMETRY_ERROR_R,
    n_heldout: int = DEFAULT_HELDOUT,
    rig: StereoRig | None = None,
    ranges: Mapping[str, tuple[float, float]] | None = None,
    world_to_base: CPCParams | None = None,
    require_view: bool = True,
    robot_ref: str | None = None,
    show_progress: bool = False,
) -> Experiment:
    """Simulate a stage-1 calibration experiment in memory (no files).

    Random streams for the true geometry, the measurement noise and the held-out configurations
    are independent children of ``seed``: changing the noise keeps the same true robot.

    Args:
        robot: Shipped robot name, robot spec/model path, a :class:`RobotSpec`, or a nominal
            :class:`CPCModel`. Needs nominal geometry.
        seed: Seed of everything random.
        M: Values per joint in the one-joint-at-a-time protocol (n M + 1 records).
        noise: ``"fig10"``, ``"stereo"`` or ``"none"``.
        sigma_t: Fig. 10 translation noise per entry [m].
        sigma_r: Fig. 10 rotation noise angle [rad].
        pixel_sigma: Stereo pixel noise per coordinate [px].
        geometry_error_t: Std of each component of each CPC offset error of the true robot [m].
        geometry_error_r: Std of the rotation error angle of each CPC placement [rad].
        n_heldout: Number of random held-out configurations (true poses, no noise).
        rig: The measuring rig (default :meth:`StereoRig.verged`: 600 mm baseline, 1.5 m).
        ranges: Calibration ranges per joint ``{name: (lo, hi)}`` [m]/[rad] overriding the spec.
        world_to_base: Nominal placement in the rig's world (default: :func:`clear_placement`
            over the protocol and a fixed sample of the calibration ranges, so that no plate
            hides another's circles); the true placement is this plus geometric error.
        require_view: Raise if a plate leaves the view of a camera or a circle is hidden
            (otherwise just record it).
        robot_ref: Robot reference written into the measurement sets (default: ``robot`` if
            it is a name or path).
        show_progress: Draw a progress bar on stderr.

    Returns:
        ``Experiment(truth, measured, heldout)``.

    Raises:
        ConfigurationError: A plate leaves the view of a camera, or a circle is hidden, in some
            configuration (the message names the plate and configuration), or bad arguments.
        SpecError: The robot has no nominal geometry.
    """
    if noise not in NOISE_MODELS:
        raise ConfigurationError(f"noise model must be one of {NOISE_MODELS}, got {noise!r}")
    for name, v in (("sigma_t", sigma_t), ("sigma_r", sigma_r), ("pixel_sigma", pixel_sigma),
                    ("geometry_error_t", geometry_error_t), ("geometry_error_r", geometry_error_r)):
        if not (math.isfinite(v) and v >= 0):
            raise ConfigurationError(f"{name} must be a finite number >= 0, got {v}")
    if n_heldout < 0:
        raise ConfigurationError(f"n_heldout must be >= 0, got {n_heldout}")
    spec, ref = _as_spec(robot)
    ref = robot_ref or ref
    nominal = spec.nominal_model()
    s = nominal.structure
    frames = measured_frames(s)
    if not frames:
        raise ConfigurationError(f"robot {s.name!r} has no frame of kind 'plate' to measure")
    rig = rig or StereoRig.verged()
    r = calibration_ranges(s, ranges)
    q, labels = protocol_configurations(r, M, s.joint_names)
    rng_geometry, rng_noise, rng_heldout = (np.random.default_rng(c) for c in np.random.SeedSequence(seed).spawn(3))

    # The placement depends on the robot, rig and ranges only (a fixed sample), not on the seed.
    q_sample = random_configurations(r, 256, np.random.default_rng(0))
    w2b = world_to_base or _memo_clear_placement(nominal, rig, q, frames, q_sample)
    truth = perturbed_model(nominal.with_params(world_to_base=w2b), rng_geometry, geometry_error_t, geometry_error_r)
    q_held, redrawn = visible_heldout(truth, rig, r, n_heldout, frames, rng_heldout)
    view = check_view(truth, rig, np.vstack([q, q_held]), frames,
                      labels + [f"heldout {i}" for i in range(n_heldout)])
    # A plate outside an image or seen edge-on cannot be measured: refuse. A circle hidden by the
    # other plate in an occasional view of this particular true robot (the placement was searched
    # clear on the nominal one) leaves that plate measurable from its other circles: recorded in
    # the provenance. Plates hiding each other in more than OCCLUDED_VIEWS_MAX of the views is a
    # bad experiment design: refused too.
    unmeasurable = view.problems[: view.unseen]
    occluded = view.problems[view.unseen:]
    if len(occluded) > OCCLUDED_VIEWS_MAX * (len(q) + n_heldout) * len(frames):
        unmeasurable += occluded
    if require_view and unmeasurable:
        more = f" (and {len(unmeasurable) - 1} more)" if len(unmeasurable) > 1 else ""
        raise ConfigurationError(
            f"the rig does not see {unmeasurable[0]}{more}; narrow the calibration ranges, "
            "widen the rig's field of view or place the robot differently"
        )

    # Measure joint by joint so that a long run shows progress (the protocol's blocks).
    blocks = [np.arange(1)] + [1 + i * M + np.arange(M) for i in range(s.n_joints)]
    items = progress(blocks, "simulate") if show_progress else blocks
    parts = [measure_poses(truth, q[b], frames, rng_noise, noise=noise, sigma_t=sigma_t, sigma_r=sigma_r,
                           rig=rig, pixel_sigma=pixel_sigma) for b in items]
    poses = {f: np.concatenate([p[0][f] for p in parts]) for f in frames}
    points = {f: np.concatenate([p[1][f] for p in parts]) for f in parts[0][1]}

    noise_doc: dict[str, Any] = {"model": noise}
    if noise == "fig10":
        noise_doc.update(sigma_t_m=sigma_t, sigma_r_rad=sigma_r)
    elif noise == "stereo":
        noise_doc.update(pixel_sigma_px=pixel_sigma)
    provenance = {
        "simulator": "cpc2urdf.identification.simulation.simulate",
        "seed": seed,
        "M": M,
        "protocol": "one joint at a time from q0 (Shih et al. sec. 4.1)",
        "calibration_ranges": {n: [float(a), float(b)] for n, (a, b) in zip(s.joint_names, r, strict=True)},
        "geometry_error": {"sigma_t_m": geometry_error_t, "sigma_r_rad": geometry_error_r},
        "rig": rig.to_json(),
        "view": {"min_margin_px": view.min_margin_px, "max_view_angle_rad": view.max_view_angle,
                 "distance_range_m": list(view.distance_range), "problems": view.problems[:10],
                 "hidden_circle_sightings": view.hidden,
                 "heldout_redrawn_unmeasurable": redrawn},
    }
    fit_rms = {}
    if points:
        from cpc2urdf.registration import registration_rms

        for f, P in points.items():
            fit_rms[f] = registration_rms(poses[f], np.array(s.frame(f).layout), P)
    measured = MeasurementSet(s, q, poses, "<simulated>", ref, labels, points, fit_rms,
                              {"description": f"simulated stage-1 measurements of {s.name}",
                               "noise": noise_doc, "provenance": provenance})
    held_true = truth.fk(q_held, frames) if n_heldout else {f: np.empty((0, 4, 4)) for f in frames}
    heldout = MeasurementSet(
        s, q_held.reshape(-1, s.n_joints), held_true, "<simulated heldout>", ref,
        [f"heldout {i}" for i in range(n_heldout)],
        metadata={"description": f"held-out configurations of {s.name} with TRUE poses (no noise)",
                  "noise": {"model": "none"}, "provenance": {**provenance, "seed_stream": "heldout"}},
    )
    truth = truth.with_params(metadata={
        **nominal.metadata,
        "provenance": {"simulated_truth": True, "seed": seed, "nominal": ref,
                       "geometry_error": provenance["geometry_error"],
                       "nominal_world_to_base": {"b": list(w2b.b), "beta": w2b.beta, "l": list(w2b.l)}},
    })
    return Experiment(truth, measured, heldout)
