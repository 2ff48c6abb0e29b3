"""Study: standard boards (chessboard, ChArUco, circle grids) from rendered images, both stages.

Everything is rendered (:func:`~cpc2urdf.identification.vision.render.render_board_view`: blur
0.7 px, grey noise 2/255, lens distortion) and measured with OpenCV's detectors
(:mod:`~cpc2urdf.identification.vision.boards.board_poses`). Reported:

1. per board kind, single-camera poses (the stage-2 head camera, 640 x 480, f = 500 px,
   k1 = -0.1) against what the detector's own pixel noise predicts through the PnP Jacobian
   (:func:`~cpc2urdf.identification.vision.boards.board_poses.pnp_pose_covariance`);
2. ``cv2.calibrateCamera`` on ChArUco views: the intrinsics' errors next to OpenCV's standard
   deviations;
3. ``cv2.stereoCalibrate`` of the paper's rig (1280 x 1024, f = 1600 px, 600 mm baseline): the
   errors of ``T`` and ``R`` next to a Monte Carlo on exact corners with the detector's noise;
4. stage 1: the IIS-head with two ChArUco plates, closed-form identification from the images vs
   from the exact poses of the same records through the rig with the same pixel noise (5 draws);
5. stage 2: camera frames (hand-eye) from ChArUco target images vs from exact target poses with
   the same pixel noise (5 draws).

    cpc2urdf study boards [--views 16] [--M 3] [--seed 0] [--out study_boards]

Writes ``boards.md`` into ``--out`` and prints it.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from cpc2urdf.argparsing import OneLineParser
from cpc2urdf.identification.vision.image_folders import read_grey

BOARDS: dict[str, dict[str, Any]] = {
    "chessboard 9 x 6, 20 mm": {"kind": "chessboard", "pattern_size": [9, 6], "square_size": 20},
    "ChArUco 7 x 5, 30 mm": {
        "kind": "charuco",
        "squares": [7, 5],
        "square_size": 30,
        "marker_size": 22,
        "dictionary": "DICT_5X5_100",
    },
    "asymmetric circles 4 x 11, 15 mm": {
        "kind": "asymmetric_circles",
        "pattern_size": [4, 11],
        "spacing": 15,
        "circle_radius": 5,
    },
    "circles 7 x 5, 25 mm (up to 180 deg)": {
        "kind": "circles",
        "pattern_size": [7, 5],
        "spacing": 25,
        "circle_radius": 7,
    },
}
PLATE = {
    "kind": "charuco",
    "squares": [4, 4],
    "square_size": 40,
    "marker_size": 30,
    "dictionary": "DICT_4X4_50",
    "margin": 10,
}
RIG_BOARD = {
    "kind": "charuco",
    "squares": [9, 7],
    "square_size": 40,
    "marker_size": 30,
    "dictionary": "DICT_5X5_100",
}


def _board(doc: dict[str, Any], name: str, **extra: Any) -> Any:
    from cpc2urdf.identification.vision.boards.board_file import board_from_json

    return board_from_json({"format": "cpc2urdf/board@1", "units": "mm", **doc, **extra}, name)


def _single_camera(views: int, seed: int) -> list[dict[str, Any]]:
    from scipy.spatial.transform import Rotation

    from cpc2urdf.identification.simulation.image_experiment import random_board_poses
    from cpc2urdf.identification.vision.boards.board_poses import board_pose, pnp_pose_covariance
    from cpc2urdf.identification.vision.render import PinholeView, render_board_view

    K = np.array([[500.0, 0.0, 319.5], [0.0, 500.0, 239.5], [0.0, 0.0, 1.0]])
    D = np.array([-0.1, 0.05, 0.0, 0.0, 0.0])
    view = PinholeView(K, D, (640, 480), np.eye(4))
    rows = []
    for name, doc in BOARDS.items():
        b = _board(doc, name)
        rng = np.random.default_rng(seed)
        poses = random_board_poses([view], b, views, rng, distance=(0.35, 0.6))
        res, errs, pred, maha = [], [], [], []
        for T in poses:
            r = board_pose(
                render_board_view(view, [(b, T)], blur_sigma=0.7, noise_sigma=2.0, rng=rng),
                K,
                D,
                b,
                allow_symmetric=True,
            )
            if isinstance(r, Exception):
                continue
            Te = r.T_camera_board
            truth = view.project(b.object_points() @ T[:3, :3].T + T[:3, 3])
            if b.pose_ambiguity:  # symmetric grid: the nearer of the two equal fits, nearest points
                flip = Te @ np.diag([-1.0, -1.0, 1.0, 1.0])
                rv = [
                    np.linalg.norm(Rotation.from_matrix(X[:3, :3] @ T[:3, :3].T).as_rotvec())
                    for X in (Te, flip)
                ]
                Te = flip if rv[1] < rv[0] else Te
                res.append(
                    r.uv - truth[np.argmin(((r.uv[:, None] - truth[None]) ** 2).sum(-1), axis=1)]
                )
            else:
                res.append(r.uv - truth[r.ids])
            errs.append(
                (
                    T,
                    np.concatenate(
                        [
                            Rotation.from_matrix(Te[:3, :3] @ T[:3, :3].T).as_rotvec(),
                            Te[:3, 3] - T[:3, 3],
                        ]
                    ),
                    r.ids,
                )
            )
        sigma = float(np.sqrt(np.mean(np.concatenate(res) ** 2)))
        for T, e, ids in errs:
            C = pnp_pose_covariance(K, D, T, b.object_points()[ids], sigma)
            pred.append((np.trace(C[:3, :3]), np.trace(C[3:, 3:])))
            maha.append(float(e @ np.linalg.solve(C, e)) / 6)
        E = np.array([e for _, e, _ in errs])
        P = np.array(pred)
        rows.append(
            {
                "board": name,
                "views": len(errs),
                "sigma_px": sigma,
                "pos_rms_mm": float(np.sqrt(np.mean(np.sum(E[:, 3:] ** 2, 1)))) * 1e3,
                "pred_pos_rms_mm": float(np.sqrt(np.mean(P[:, 1]))) * 1e3,
                "rot_rms_deg": float(np.degrees(np.sqrt(np.mean(np.sum(E[:, :3] ** 2, 1))))),
                "pred_rot_rms_deg": float(np.degrees(np.sqrt(np.mean(P[:, 0])))),
                "maha": float(np.mean(maha)),
            }
        )
    return rows


def _camera_calibration(tmp: Path, views: int, seed: int) -> dict[str, Any]:
    from cpc2urdf.identification.handeye.stage2 import CameraIntrinsics
    from cpc2urdf.identification.simulation.image_experiment import render_board_calibration
    from cpc2urdf.identification.vision.camera_calibration import calibrate_camera_images

    cam = CameraIntrinsics(dist=(-0.1, 0.05, 0.0, 0.0, 0.0))
    b = _board(BOARDS["ChArUco 7 x 5, 30 mm"], "charuco")
    render_board_calibration(tmp / "cam", b, camera=cam, n_views=views, seed=seed)
    c = calibrate_camera_images(tmp / "cam", b)
    err = np.array(
        [
            c.K[0, 0] - cam.fx,
            c.K[1, 1] - cam.fy,
            c.K[0, 2] - cam.cx,
            c.K[1, 2] - cam.cy,
            c.D[0] - cam.dist[0],
            c.D[1] - cam.dist[1],
        ]
    )
    return {"views": len(c.view_rms), "rms": c.rms, "err": err, "std": c.std_intrinsics[:6]}


def _rig_calibration(tmp: Path, views: int, seed: int) -> dict[str, Any]:
    import cv2
    from scipy.spatial.transform import Rotation

    from cpc2urdf.identification.simulation.image_experiment import render_board_calibration
    from cpc2urdf.identification.vision.boards.board_poses import detect_board
    from cpc2urdf.identification.vision.camera_calibration import calibrate_rig_images
    from cpc2urdf.identification.vision.stereo import StereoRig

    rig = StereoRig.verged()
    b = _board(RIG_BOARD, "charuco9x7")
    T = render_board_calibration(tmp / "rig", b, rig=rig, n_views=views, seed=seed)
    cal = calibrate_rig_images(tmp / "rig", b)
    P = b.object_points()
    res = []
    for i, Ti in enumerate(T):
        img = read_grey(tmp / "rig" / "left" / f"{i:04d}.png")
        d = detect_board(img, b)
        if not isinstance(d, Exception):
            res.append(d.uv - rig.project(P[d.ids] @ Ti[:3, :3].T + Ti[:3, 3])[0])
    sigma = float(np.sqrt(np.mean(np.concatenate(res) ** 2)))
    rng = np.random.default_rng(seed + 7)
    dt, dr = [], []
    for _ in range(10):  # Monte Carlo on exact corners with the detector's noise, the same pipeline
        obj: list[np.ndarray] = []
        pts: list[list[np.ndarray]] = [[], []]
        for Ti in T:
            uv = rig.project(P @ Ti[:3, :3].T + Ti[:3, 3])
            obj.append(P.astype(np.float32).reshape(-1, 1, 3))
            for k in range(2):
                pts[k].append(
                    (uv[k] + rng.normal(0, sigma, uv[k].shape)).astype(np.float32).reshape(-1, 1, 2)
                )
        mono = [
            cv2.calibrateCamera(
                obj, p, rig.image_size, np.eye(3), np.zeros(5), flags=cv2.CALIB_FIX_K3
            )[1:3]
            for p in pts
        ]
        r = cv2.stereoCalibrate(
            obj,
            pts[0],
            pts[1],
            mono[0][0],
            mono[0][1],
            mono[1][0],
            mono[1][1],
            rig.image_size,
            np.eye(3),
            np.zeros((3, 1)),
            flags=cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_K3,
        )
        dt.append(np.linalg.norm(np.asarray(r[6]).ravel() - rig.T))
        dr.append(np.linalg.norm(Rotation.from_matrix(np.asarray(r[5]) @ rig.R.T).as_rotvec()))
    return {
        "views": len(cal.view_rms),
        "rms": cal.rms,
        "sigma": sigma,
        "err_t_mm": float(np.linalg.norm(cal.rig.T - rig.T)) * 1e3,
        "err_r_deg": float(
            np.degrees(np.linalg.norm(Rotation.from_matrix(cal.rig.R @ rig.R.T).as_rotvec()))
        ),
        "mc_t_mm": float(np.sqrt(np.mean(np.square(dt)))) * 1e3,
        "mc_r_deg": float(np.degrees(np.sqrt(np.mean(np.square(dr))))),
        "outliers": cal.outliers,
    }


def _stage1(tmp: Path, M: int, seed: int) -> dict[str, Any]:

    from cpc2urdf.files.measurements import MeasurementSet
    from cpc2urdf.identification.kinematics.closed_form import identify_closed_form
    from cpc2urdf.identification.simulation.image_experiment import render_board_experiment
    from cpc2urdf.identification.simulation.measurement_noise import stereo_noise
    from cpc2urdf.identification.vision.boards.board_poses import board_pose
    from cpc2urdf.identification.vision.measure_stereo import measure_stereo_images
    from cpc2urdf.validation.heldout import accuracy

    boards = {
        "plate_left": _board(PLATE, "left", first_marker_id=0),
        "plate_right": _board(PLATE, "right", first_marker_id=8),
    }
    exp = render_board_experiment(tmp / "stage1", boards, M=M, n_heldout=30, seed=seed)
    s = exp.truth.structure
    meas = measure_stereo_images(tmp / "stage1", exp.rig, s, boards=boards)
    ms = meas.measurements
    rig = exp.rig
    res = []
    for i in range(exp.measured.n_records):
        for k, side in enumerate(("left", "right")):
            img = read_grey(tmp / "stage1" / side / f"{i:04d}.png")
            for f, b in boards.items():
                r = board_pose(img, *((rig.K1, rig.D1) if k == 0 else (rig.K2, rig.D2)), b)
                if not isinstance(r, Exception):
                    T = exp.measured.poses[f][i]
                    res.append(
                        r.uv - rig.project(b.object_points()[r.ids] @ T[:3, :3].T + T[:3, 3])[k]
                    )
    sigma = float(np.sqrt(np.mean(np.concatenate(res) ** 2)))

    def score(m: MeasurementSet) -> dict[str, float]:
        model, _ = identify_closed_form(m)
        return {f: a.rms * 1e3 for f, a in accuracy(model, exp.heldout).items()}

    from_images = score(ms)
    # the reference: the records and plates the images measured, exact poses + the same pixel noise
    idx = [exp.measured.labels.index(lab) for lab in ms.labels]
    ref = []
    for k in range(5):
        rk = np.random.default_rng(1000 + k)
        poses = {}
        for f, b in boards.items():
            P = stereo_noise(exp.measured.poses[f][idx], b.object_points(), rig, sigma, rk)[0]
            P[~ms.has_pose(f)] = np.nan
            poses[f] = P
        ref.append(score(MeasurementSet(s, ms.q, poses, labels=ms.labels)))
    return {
        "records": exp.measured.n_records,
        "measured": ms.n_records,
        "skipped": len(meas.problems),
        "sigma": sigma,
        "from_images": from_images,
        "ref": ref,
        "plates": {f: int(ms.has_pose(f).sum()) for f in boards},
    }


def _stage2(tmp: Path, n_poses: int, seed: int) -> dict[str, Any]:
    import json

    import cv2

    from cpc2urdf.identification.handeye.head_images import stage2_observations
    from cpc2urdf.identification.handeye.stage2 import (
        DEFAULT_INTRINSICS,
        Stage2Observations,
        calibrate_cameras,
        camera_errors,
    )
    from cpc2urdf.identification.simulation.image_experiment import render_head_board_experiment
    from cpc2urdf.identification.simulation.stage1_experiment import simulate_experiment
    from cpc2urdf.identification.vision.boards.board_poses import board_pose, solve_pnp
    from cpc2urdf.identification.vision.measure_head import HeadCamera, measure_head_images
    from cpc2urdf.transforms import inverse

    truth = simulate_experiment("iis_head", seed=seed, M=2, noise="none", n_heldout=1)[0]
    b = _board(BOARDS["ChArUco 7 x 5, 30 mm"], "charuco")
    render_head_board_experiment(tmp / "head", truth, b, n_poses=n_poses, seed=seed + 3)
    intr = DEFAULT_INTRINSICS
    cameras = ("camera_left_optical", "camera_right_optical")
    cams = {c: HeadCamera(intr.K, intr.D, (intr.width, intr.height)) for c in cameras}
    obs = stage2_observations(
        measure_head_images(tmp / "head", cams, truth.structure, board=b), cams
    )
    model, _ = calibrate_cameras(truth.without_frames(["camera"]), obs, "tsai")
    from_images = camera_errors(model, truth, list(cameras))
    T_bt = np.array(json.loads((tmp / "head" / "target_truth.json").read_text())["T_base_target"])
    C = {
        c: inverse(inverse(truth.T_world_base())[None] @ truth.fk_frame(c, obs.q)) @ T_bt
        for c in cameras
    }
    P = b.object_points()
    res = []
    for c in cameras:
        for i, Ci in enumerate(C[c]):
            r = board_pose(read_grey(tmp / "head" / c / f"{i:04d}.png"), intr.K, intr.D, b)
            if not isinstance(r, Exception):
                uv, _ = cv2.projectPoints(
                    P[r.ids], cv2.Rodrigues(Ci[:3, :3])[0], Ci[:3, 3], intr.K, intr.D
                )
                res.append(r.uv - uv.reshape(-1, 2))
    sigma = float(np.sqrt(np.mean(np.concatenate(res) ** 2)))
    ref = []
    for k in range(5):
        rk = np.random.default_rng(100 + k)
        poses = {}
        for c in cameras:
            Ts = []
            for Ci in C[c]:
                uv, _ = cv2.projectPoints(
                    P, cv2.Rodrigues(Ci[:3, :3])[0], Ci[:3, 3], intr.K, intr.D
                )
                Ts.append(
                    solve_pnp(
                        P, uv.reshape(-1, 2) + rk.normal(0.0, sigma, (len(P), 2)), intr.K, intr.D
                    )[0]
                )
            poses[c] = np.array(Ts)
        o = Stage2Observations(obs.q, poses, {}, intr, sigma, T_bt)
        ref.append(
            camera_errors(
                calibrate_cameras(truth.without_frames(["camera"]), o, "tsai")[0],
                truth,
                list(cameras),
            )
        )
    return {"poses": len(obs.q), "sigma": sigma, "from_images": from_images, "ref": ref}


def run_study(*, views: int = 16, M: int = 3, seed: int = 0) -> dict[str, Any]:
    """Run the study; returns the numbers and a markdown report under ``"md"``."""
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        single = _single_camera(views, seed)
        cam = _camera_calibration(tmp, views, seed)
        rig = _rig_calibration(tmp, max(views // 2, 6), seed)
        st1 = _stage1(tmp, M, seed)
        st2 = _stage2(tmp, views, seed)
    md = [
        "# Standard boards from rendered images (`cpc2urdf study boards`)",
        "",
        f"Images: Gaussian blur 0.7 px, grey noise 2/255, 8-bit. Seed {seed}.",
        "",
        f"## Single-camera poses ({views} random views per board; 640 x 480, f = 500 px, k1 = -0.1, 0.35-0.6 m)",
        "",
        "Predicted: the PnP Jacobian with the detector's measured pixel noise (sigma per coordinate). "
        "Mahalanobis: mean of e^T C^-1 e / 6 over the views (1 when the poses are as good as the noise allows).",
        "",
        "| board | views | sigma [px] | position RMS [mm] | predicted | rotation RMS [deg] | predicted | Mahalanobis / 6 |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in single:
        md.append(
            f"| {r['board']} | {r['views']} | {r['sigma_px']:.4f} | {r['pos_rms_mm']:.4f} | {r['pred_pos_rms_mm']:.4f} | "
            f"{r['rot_rms_deg']:.4f} | {r['pred_rot_rms_deg']:.4f} | {r['maha']:.2f} |"
        )
    names = ("fx", "fy", "cx", "cy", "k1", "k2")
    md += [
        "",
        f"## calibrateCamera (ChArUco 7 x 5, {cam['views']} views, RMS {cam['rms']:.3f} px)",
        "",
        "| | " + " | ".join(names) + " |",
        "|---|" + "---|" * len(names),
        "| error | " + " | ".join(f"{e:+.4g}" for e in cam["err"]) + " |",
        "| OpenCV std | " + " | ".join(f"{e:.4g}" for e in cam["std"]) + " |",
        "",
        f"## stereoCalibrate (paper rig, ChArUco 9 x 7 x 40 mm, {rig['views']} views at 1.2-1.8 m, RMS {rig['rms']:.3f} px)",
        "",
        f"Detector noise {rig['sigma']:.4f} px. |T error| {rig['err_t_mm']:.3f} mm (Monte Carlo on exact corners with that "
        f"noise, RMS: {rig['mc_t_mm']:.3f} mm); R error {rig['err_r_deg']:.4f} deg (Monte Carlo {rig['mc_r_deg']:.4f} deg). "
        f"Views named as bad: {len(rig['outliers'])}.",
        "",
        f"## Stage 1: two ChArUco plates (4 x 4 x 40 mm, DICT_4X4_50) on the IIS-head, M = {M}",
        "",
        f"{st1['records']} records rendered, {st1['measured']} with a plate measured ({st1['plates']}), "
        f"{st1['skipped']} plate views refused (a board hiding corners of the other, or seen too obliquely). Detector "
        f"noise {st1['sigma']:.4f} px. Held-out positioning error RMS [mm], closed form, 30 configurations:",
        "",
        "| plate | from the images | exact poses + the same noise: median of 5 | range |",
        "|---|---|---|---|",
    ]
    for f, v in st1["from_images"].items():
        vals = [r[f] for r in st1["ref"]]
        md.append(f"| {f} | {v:.4f} | {np.median(vals):.4f} | {min(vals):.4f} - {max(vals):.4f} |")
    md += [
        "",
        f"## Stage 2: ChArUco 7 x 5 target, {st2['poses']} configurations, camera frames (Tsai)",
        "",
        f"Detector noise {st2['sigma']:.4f} px.",
        "",
        "| camera | from the images [mm, deg] | exact poses + the same noise: median of 5 | range [mm] |",
        "|---|---|---|---|",
    ]
    for c, (t, r) in st2["from_images"].items():
        ts = [x[c][0] * 1e3 for x in st2["ref"]]
        rs = [np.degrees(x[c][1]) for x in st2["ref"]]
        md.append(
            f"| {c} | {t * 1e3:.3f}, {np.degrees(r):.4f} | {np.median(ts):.3f}, {np.median(rs):.4f} | "
            f"{min(ts):.3f} - {max(ts):.3f} |"
        )
    md.append("")
    return {
        "single": single,
        "camera": cam,
        "rig": rig,
        "stage1": st1,
        "stage2": st2,
        "md": "\n".join(md),
    }


def main(argv: list[str] | None = None) -> int:
    """``cpc2urdf study boards [--views N] [--M M] [--seed S] [--out DIR]``."""
    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.jsonio import make_folder, write_atomic

    parser = OneLineParser(
        prog="cpc2urdf study boards",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--views",
        type=int,
        default=16,
        help="views per board, camera-calibration views and stage-2 configurations (default 16)",
    )
    parser.add_argument(
        "--M", type=int, default=3, help="values per joint of the stage-1 experiment (default 3)"
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument(
        "--out", default="study_boards", help="output folder (default study_boards)"
    )
    args = parser.parse_args(argv)
    if args.views < 6 or args.M < 2:
        raise ConfigurationError("--views must be >= 6 and --M >= 2")
    out = Path(args.out)
    make_folder(out)
    result = run_study(views=args.views, M=args.M, seed=args.seed)
    path = write_atomic(out / "boards.md", result["md"])
    print(result["md"])
    print(f"wrote {path}")
    return 0


__all__ = ["main", "run_study"]
