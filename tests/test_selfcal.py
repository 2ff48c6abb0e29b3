"""The one-stage calibration on pixels (cpc2urdf.identification.selfcal): its Jacobian against
finite differences, exact recovery from exact corners (board fixed or held by the robot),
outliers named, the parameters the images do not determine kept, the gate's causes, and the
covariance against the spread of repeated fits."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from cpc2urdf.errors import InconsistentDataError
from cpc2urdf.files.robot_ref import load_robot
from cpc2urdf.identification.handeye import stage2
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.selfcal.bundle import fit_pixels
from cpc2urdf.identification.selfcal.calibrate import calibrate_head
from cpc2urdf.identification.selfcal.pixel_problem import (
    BoardView,
    CameraModel,
    PixelData,
    PixelProblem,
)
from cpc2urdf.identification.simulation.truth import perturbed_model
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.model import CPCModel, CPCParams, Frame
from cpc2urdf.transforms import inverse, rotation_error

BOARD = Board("chessboard", (9, 6), square_size=0.03)
CAMERAS = list(stage2.HAND_OF_CAMERA)
INTR = stage2.DEFAULT_INTRINSICS
CAMERA = CameraModel(INTR.K, np.array([0.05, -0.1, 0.0, 0.0, 0.0]), (INTR.width, INTR.height))


def views(model: CPCModel, q, noise: float, rng, board_frame: str | None = None) -> list[BoardView]:
    """Each camera's exact corners at ``q`` plus Gaussian noise of ``noise`` px."""
    X = BOARD.object_points()
    T = model.fk(q, CAMERAS + ([board_frame] if board_frame else []))
    out = []
    for c in CAMERAS:
        for r in range(len(q)):
            Tb = T[board_frame][r] if board_frame else np.eye(4)
            Xc = (X @ Tb[:3, :3].T + Tb[:3, 3] - T[c][r][:3, 3]) @ T[c][r][:3, :3]
            uv, _ = cv2.projectPoints(
                Xc.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), CAMERA.K, CAMERA.D
            )
            uv = uv.reshape(-1, 2) + rng.normal(0.0, noise, (len(X), 2))
            out.append(BoardView(c, r, np.arange(len(X)), uv))
    return out


def scene(seed: int = 1, held: bool = False) -> tuple[CPCModel, CPCModel, str | None]:
    """(nominal, truth, board frame): the IIS-head with the board fixed (the world is the board) or
    held on the pan link in front of the cameras."""
    nom = load_robot("iis_head").nominal
    assert nom is not None
    T_base_board = stage2.default_target_placement(nom, CAMERAS)
    if held:
        home = stage2.home_configuration(nom)[None]
        at = nom.with_frame(Frame("board", "pan", "frame"), CPCParams.from_matrix(np.eye(4)))
        placed = inverse(at.fk_frame("board", home)[0]) @ nom.T_world_base() @ T_base_board
        nom = nom.with_frame(Frame("board", "pan", "frame"), CPCParams.from_matrix(placed))
    else:
        nom = nom.with_params(world_to_base=CPCParams.from_matrix(inverse(T_base_board)))
    truth = perturbed_model(nom, np.random.default_rng(seed), 1e-3, np.radians(0.5))
    if not held:
        truth = truth.with_params(world_to_base=nom.world_to_base)
    return nom, truth, "board" if held else None


def data_of(truth: CPCModel, q, noise: float, seed: int, board_frame=None) -> PixelData:
    rng = np.random.default_rng(seed)
    return PixelData(
        q,
        [f"r{i}" for i in range(len(q))],
        views(truth, q, noise, rng, board_frame),
        {c: CAMERA for c in CAMERAS},
        BOARD.object_points(),
        board_frame,
    )


def configurations(n: int, seed: int):
    """Configurations in which both cameras see the whole fixed board (a held one stays near)."""
    nom = scene()[0]
    T = inverse(nom.T_world_base())
    return stage2.sample_configurations(nom, n, np.random.default_rng(seed), T, cameras=CAMERAS)


def pose_errors(a: CPCModel, b: CPCModel, q, board_frame=None) -> tuple[float, float]:
    """RMS over cameras and ``q`` of the camera pose in the board's frame: [m], [rad]."""
    dp, dr = [], []
    for c in CAMERAS:
        Ta, Tb = (
            inverse(m.fk_frame(board_frame, q)) @ m.fk_frame(c, q)
            if board_frame
            else m.fk_frame(c, q)
            for m in (a, b)
        )
        dp += list(np.linalg.norm(Ta[:, :3, 3] - Tb[:, :3, 3], axis=1))
        dr += [rotation_error(x[:3, :3], y[:3, :3]) for x, y in zip(Ta, Tb, strict=True)]
    return float(np.sqrt(np.mean(np.square(dp)))), float(np.sqrt(np.mean(np.square(dr))))


@pytest.mark.parametrize("held", [False, True])
def test_jacobian_matches_finite_differences(held):
    nom, truth, bf = scene(held=held)
    q = configurations(5, 0)
    data = data_of(truth, q, 0.1, 0, bf)
    chart = Parametrization(nom, CAMERAS + ([bf] if bf else []))
    use = [np.ones(len(v.ids), dtype=bool) for v in data.views]
    prob = PixelProblem(chart, data, use, np.full(len(data.views), 0.1), intrinsics=True)
    x = np.random.default_rng(3).normal(0.0, 1e-3, prob.n_params)
    J = prob.jacobian(x)
    h = 1e-7
    Jn = np.column_stack(
        [
            (prob.residuals(x + h * e) - prob.residuals(x - h * e)) / (2 * h)
            for e in np.eye(prob.n_params)
        ]
    )
    assert np.abs(J - Jn).max() < 1e-6 * np.abs(J).max()


@pytest.mark.parametrize("held", [False, True])
def test_exact_corners_recover_the_head(held):
    nom, truth, bf = scene(held=held)
    q = configurations(12, 0)
    data = data_of(truth, q, 0.0, 0, bf)
    start = calibrate_head(nom, data).model
    fit = fit_pixels(start, data)
    held_out = configurations(20, 5)
    dp, dr = pose_errors(fit.model, truth, held_out, bf)
    before = pose_errors(nom, truth, held_out, bf)
    assert dp < 1e-8 and dr < 1e-9, (dp, dr)
    assert before[0] > 1e-3  # the nominal head was millimetres off
    assert not fit.outliers
    if held:  # only relative poses: the rigid motion of everything is not determined
        assert fit.undetermined and fit.null_space.shape[1] >= 6
    else:
        assert not fit.undetermined


def test_outliers_are_named_and_dropped():
    nom, truth, _ = scene()
    q = configurations(12, 0)
    data = data_of(truth, q, 0.1, 0)
    data.views[3].uv[7] += (4.0, -3.0)  # a misdetected corner
    data.views[5].uv[:] += np.random.default_rng(0).normal(0.0, 1.5, data.views[5].uv.shape)  # blur
    clean = data_of(truth, q, 0.1, 0)
    fit = fit_pixels(nom, data)
    said = " | ".join(fit.outliers)
    assert f"corner 7 of image {data.view_name(3)}" in said
    assert f"image {data.view_name(5)}:" in said and "blurred" in said
    assert len(fit.outliers) == 2, said
    assert not fit_pixels(nom, clean).outliers
    assert (
        pose_errors(fit.model, truth, q)[0]
        < 2 * pose_errors(fit_pixels(nom, clean).model, truth, q)[0]
    )


def test_a_joint_that_never_moves_keeps_the_users_values():
    nom, truth, _ = scene()
    q = configurations(12, 0)
    q[:, nom.structure.joint_index("table_y")] = q[0, nom.structure.joint_index("table_y")]
    fit = fit_pixels(nom, data_of(truth, q, 0.1, 0))
    assert {"table_y.b_x", "table_y.b_y"} <= set(fit.undetermined)
    assert fit.model.joints["table_y"].matrix()[:3, :3] == pytest.approx(
        nom.joints["table_y"].matrix()[:3, :3], abs=1e-12
    )


def test_intrinsics_that_do_not_fit_the_images_are_named():
    nom, truth, _ = scene()
    q = configurations(12, 0)
    data = data_of(truth, q, 0.1, 0)
    wrong = CameraModel(CAMERA.K * [[1.08], [1.08], [1.0]], CAMERA.D, CAMERA.image_size)
    data.cameras = {c: wrong for c in CAMERAS}
    with pytest.raises(InconsistentDataError, match="the intrinsics do not fit the images"):
        calibrate_head(nom, data)
    fitted = calibrate_head(nom, data, intrinsics=True)
    fx = fitted.fit.cameras[CAMERAS[0]].K[0, 0]
    assert fx == pytest.approx(CAMERA.K[0, 0], abs=1.0)


def test_covariance_matches_the_spread_of_repeated_fits():
    """Mahalanobis distance of held-out camera poses, 12 seeds: its mean is the pose dimension
    when the covariance is right (within 1.2x in the RMS error)."""
    nom, truth, _ = scene()
    q = configurations(10, 0)
    held_out = configurations(5, 7)
    m2 = []
    for seed in range(12):
        fit = fit_pixels(nom, data_of(truth, q, 0.1, seed))
        P = fit.chart.n_params
        T, D = fit.chart.pose_jacobian(np.zeros(P), held_out)
        Tt = truth.fk(held_out, CAMERAS)
        for c in CAMERAS:
            cov = np.einsum("nip,pq,njq->nij", D[c], fit.chart_covariance(), D[c])
            for i in range(len(held_out)):
                dR = Tt[c][i][:3, :3] @ T[c][i][:3, :3].T
                e = np.r_[Tt[c][i][:3, 3] - T[c][i][:3, 3], cv2.Rodrigues(dR)[0].ravel()]
                m2.append(e @ np.linalg.solve(cov[i], e))
    ratio = np.sqrt(np.mean(m2) / 6.0)
    assert 0.8 < ratio < 1.2, ratio


@pytest.mark.parametrize(
    ("mistake", "said"),
    [
        ("pan", "joint pan turns the other way than in the URDF"),
        ("tilt", "joint tilt turns the other way than in the URDF"),
        ("square", r"the board is about 1\.03 times the size its file says"),
        ("fx", "the intrinsics do not fit the images"),
    ],
)
def test_the_true_cause_is_named(mistake: str, said: str):
    """A reading's sign, a board printed 3 % off its file, intrinsics 3 % off: each a few % from
    the truth still fits, only worse; the gate refits the likely mistakes and names the one."""
    from dataclasses import replace

    nom, truth, _ = scene()
    data = data_of(truth, configurations(12, 0), 0.1, 0)
    if mistake in ("pan", "tilt"):
        q = data.q.copy()
        q[:, nom.structure.joint_index(mistake)] *= -1.0
        data = replace(data, q=q)
    elif mistake == "square":
        data = replace(data, board_points=data.board_points * 30.0 / 31.0)
    else:
        wrong = CameraModel(CAMERA.K * [[1.03], [1.03], [1.0]], CAMERA.D, CAMERA.image_size)
        data = replace(data, cameras={c: wrong for c in CAMERAS})
    with pytest.raises(InconsistentDataError, match=said):
        calibrate_head(nom, data)
