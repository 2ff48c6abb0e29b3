"""Where a one-stage fit starts: the board's pose in each image (PnP), then the pose pipeline.

A fixed board makes each image's PnP pose ``T_board_camera`` an end-effector pose in a world that
is the board, so the stage-1 machinery applies as it is: the closed form of Shih et al. when the
records move one joint at a time from a home configuration, else the user's model placed in the
board's world (:func:`~cpc2urdf.identification.kinematics.start.refinement_start`), then the
pose refinement (:func:`~cpc2urdf.identification.kinematics.refine.refine`). That pose fit is also
the *two-stage* answer the pixel fit is compared with. A held board's placement on its link is
the mean of what each image's PnP pose says with the user's model.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.refine import RefinementResult, refine
from cpc2urdf.identification.kinematics.start import align_base, on_the_parts, refinement_start
from cpc2urdf.identification.selfcal.pixel_problem import PixelData
from cpc2urdf.identification.vision.boards.board_poses import solve_pnp
from cpc2urdf.model import CPCModel, CPCParams
from cpc2urdf.transforms import Array, homogeneous, inverse

# Relative weights of the PnP poses (the covariance is scaled a posteriori).
PNP_SIGMA_T = 1e-3  # [m]
PNP_SIGMA_R = np.radians(0.1)  # [rad]
PNP_OUTLIER = 5.0  # an image's PnP reprojection this many times its camera's median: no start


def pnp_poses(data: PixelData) -> dict[str, Array]:
    """Camera -> ``T_camera_board`` per record by PnP (the detector's own when it solved one),
    shape (R, 4, 4); NaN where not seen, or where the pose reprojects :data:`PNP_OUTLIER` times
    worse than the camera's median image (a misdetected board: the pixel fit names it)."""
    R = len(data.q)
    out = {c: np.full((R, 4, 4), np.nan) for c in data.cameras}
    rms: dict[str, list[tuple[int, float]]] = {c: [] for c in data.cameras}
    for v in data.views:
        cam = data.cameras[v.camera]
        T, e = v.pnp or solve_pnp(data.board_points[v.ids], v.uv, cam.K, cam.D)
        out[v.camera][v.record] = T
        rms[v.camera].append((v.record, e))
    for c, found in rms.items():
        typical = float(np.median([e for _, e in found])) if found else 0.0
        for r, e in found:
            if e > PNP_OUTLIER * max(typical, 0.1):
                out[c][r] = np.nan
    return out


def pose_measurements(data: PixelData, nominal: CPCModel) -> MeasurementSet:
    """The PnP poses of a fixed board as stage-1 measurements: ``T_board_camera`` per record."""
    poses = {c: np.asarray(np.linalg.inv(T), float) for c, T in pnp_poses(data).items()}
    return MeasurementSet(
        nominal.structure, data.q, poses, source=data.source, labels=list(data.labels)
    )


def two_stage_fit(data: PixelData, nominal: CPCModel) -> tuple[RefinementResult, str, CPCModel]:
    """PnP poses, then the pose refinement: the two-stage answer, where it started, and the
    user's model placed in the board's world by the same poses (what the gate compares with).

    Raises:
        DegenerateDataError: Fewer board poses than the head's parameters need.
    """
    if data.board_frame is not None:
        raise DegenerateDataError("the pose pipeline needs a board fixed in the world")
    ms = pose_measurements(data, nominal)
    cams = list(data.cameras)
    needed = Parametrization(nominal, cams).n_params // 6 + 1
    seen = sum(int(ms.has_pose(c).sum()) for c in cams)
    if seen < needed:
        raise DegenerateDataError(
            f"{data.source}: {seen} images of the board; the head's cameras and joints need at "
            f"least {needed}"
        )
    start, kind, _ = refinement_start(ms, nominal)
    if kind == "closed-form":
        start = on_the_parts(start, nominal)
    res = refine(
        start,
        ms,
        PNP_SIGMA_T,
        PNP_SIGMA_R,
        frames=cams,
        covariance_scale="a_posteriori",
        warn=False,
    )
    return res, kind, align_base(nominal, ms, cams)


def held_board_start(data: PixelData, nominal: CPCModel) -> CPCModel:
    """``nominal`` with the held board's placement that the PnP poses say, on average."""
    assert data.board_frame is not None
    pnp = pnp_poses(data)
    frames = list(data.cameras) + [data.board_frame]
    T = nominal.fk(data.q, frames)
    corr = []
    for v in data.views:
        T_w_board = T[v.camera][v.record] @ pnp[v.camera][v.record]
        corr.append(inverse(T[data.board_frame][v.record]) @ T_w_board)
    C = np.array(corr)
    R = Rotation.from_matrix(C[:, :3, :3]).mean().as_matrix()
    fix = homogeneous(R, np.median(C[:, :3, 3], axis=0))
    placed = nominal.frames[data.board_frame].matrix() @ fix
    return nominal.with_params(frames={data.board_frame: CPCParams.from_matrix(placed)})


__all__ = ["held_board_start", "pnp_poses", "pose_measurements", "two_stage_fit"]
