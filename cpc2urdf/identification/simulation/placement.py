"""Where the robot stands in front of the stereo rig (world = the rig's left camera frame).

:func:`place_in_front_of_rig` shows the plates to the rig face-on, centred at the point where the
rig's optical axes meet. For the IIS-head that lets one plate hide part of the other, so
:func:`clear_placement` searches, in a fixed order, rolled and turned placements for one in which
both cameras see every circle over the protocol (docs/measurements.md, sec. 4, "Placement").
:func:`cached_clear_placement` remembers the search's answers: it takes about a second, and studies
simulate hundreds of experiments with the same robot, rig and configurations.

Example::

    w2b = clear_placement(nominal, StereoRig.verged(), q, ["plate_left", "plate_right"])
    placed = nominal.with_params(world_to_base=w2b)
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.identification.simulation.design import random_configurations
from cpc2urdf.identification.simulation.visibility import check_view, frame_points
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.identification.vision.targets import PlateDesign
from cpc2urdf.model import CPCModel, CPCParams
from cpc2urdf.transforms import homogeneous

Array = NDArray[np.float64]

# [px]: the placement search asks for more clearance on the nominal robot, so that the true robot
# (nominal + ~1 mm / 0.5 deg errors, a few px at 1.5 m) still keeps OCCLUSION_MARGIN_PX.
PLACEMENT_MARGIN_PX = 10.0
# Configurations of the fixed sample (seed 0, over the calibration ranges) in which the simulator's
# placement keeps as few circles as possible hidden (:func:`experiment_placement`).
PLACEMENT_SAMPLE = 256


def place_in_front_of_rig(
    model: CPCModel,
    rig: StereoRig,
    q: ArrayLike,
    frames: Sequence[str],
    *,
    up_base: ArrayLike | None = None,
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
    P = np.concatenate(
        [
            (
                np.einsum("nij,kj->nki", fk[f][:, :3, :3], frame_points(model.structure, f))
                + fk[f][:, None, :3, 3]
            ).reshape(-1, 3)
            for f in frames
        ]
    )
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


_PLACEMENTS: dict[bytes, CPCParams] = {}


def cached_clear_placement(
    model: CPCModel,
    rig: StereoRig,
    q: NDArray[np.float64],
    frames: Sequence[str],
    q_sample: NDArray[np.float64],
) -> CPCParams:
    """:func:`clear_placement` with ``q_sample``, remembered per (robot geometry, rig,
    configurations): the search takes about a second and studies simulate hundreds of
    experiments with the same inputs. The cache holds at most 65 answers (it is emptied when full).

    Args:
        model: The robot (its own ``world_to_base`` is ignored).
        rig: The measuring rig.
        q: Configurations in which every circle must be seen, shape (N, n).
        frames: The plates.
        q_sample: Further configurations in which as few circles as possible should be hidden,
            shape (M, n).
    """
    parts = [
        np.asarray(v, dtype=float).tobytes()
        for v in (rig.K1, rig.D1, rig.K2, rig.D2, rig.R, rig.T, rig.image_size, q, q_sample)
    ]
    parts += [model.joints[n].to_vector().tobytes() for n in model.structure.joint_names]
    parts += [model.frames[n].to_vector().tobytes() for n in model.structure.frame_names]
    parts += [
        repr(
            (
                model.structure.joint_names,
                [(f.name, f.layout) for f in model.structure.frames],
                tuple(frames),
            )
        ).encode()
    ]
    key = b"|".join(parts)
    if key not in _PLACEMENTS:
        if len(_PLACEMENTS) > 64:
            _PLACEMENTS.clear()
        _PLACEMENTS[key] = clear_placement(model, rig, q, frames, q_sample=q_sample)
    return _PLACEMENTS[key]


def experiment_placement(
    model: CPCModel,
    rig: StereoRig,
    q: NDArray[np.float64],
    frames: Sequence[str],
    ranges: ArrayLike,
) -> CPCParams:
    """Where the simulator places ``model`` for the protocol configurations ``q`` (N, n):
    :func:`cached_clear_placement` with a fixed sample of ``PLACEMENT_SAMPLE`` configurations drawn
    (seed 0) from the calibration ``ranges`` (n, 2), so that it depends on the robot, rig and ranges
    only, not on an experiment's seed (``simulate_experiment`` and a plan's measuring setup)."""
    q_sample = random_configurations(ranges, PLACEMENT_SAMPLE, np.random.default_rng(0))
    return cached_clear_placement(model, rig, q, frames, q_sample)


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
                view = check_view(
                    model.with_params(world_to_base=w2b),
                    rig,
                    qq,
                    frames,
                    labels,
                    occlusion_margin_px=occlusion_margin_px,
                    designs=designs,
                )
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


__all__ = [
    "PLACEMENT_MARGIN_PX",
    "PLACEMENT_SAMPLE",
    "cached_clear_placement",
    "clear_placement",
    "experiment_placement",
    "place_in_front_of_rig",
]
