"""From rendered images to measurement files, identification and hand-eye poses, end to end.

One small simulated experiment (the paper's rig, M = 3 per joint) is rendered once; then
``cpc2urdf measure`` turns it into a measurement file whose poses match the truth, and whose
identification is as accurate as identification from exact poses disturbed by the same pixel
noise. Broken inputs (corrupt, missing, blank images, a plate missing, bad rig or joints files)
give one clear line and exit code 2, or, with ``--on-error skip``, a listed skip.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from cpc2urdf.cli import main
from cpc2urdf.errors import InputFileError
from cpc2urdf.files.measurements import MeasurementSet, load_measurements
from cpc2urdf.files.robot_ref import load_model, load_robot
from cpc2urdf.identification.handeye.pose_file import load_handeye_poses
from cpc2urdf.identification.kinematics.closed_form import identify_closed_form
from cpc2urdf.identification.simulation.image_experiment import (
    RenderedExperiment,
    render_experiment,
    render_head_experiment,
)
from cpc2urdf.identification.simulation.measurement_noise import stereo_noise
from cpc2urdf.identification.vision.joints_csv import read_joints_csv, write_joints_csv
from cpc2urdf.identification.vision.render import PinholeView, circle_centres_px, render_view
from cpc2urdf.identification.vision.targets import robot_plate_designs
from cpc2urdf.transforms import inverse, rotation_error
from cpc2urdf.validation.heldout import accuracy

STRUCTURE = load_robot("iis_head").structure


@pytest.fixture(scope="module")
def experiment(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, RenderedExperiment]:
    folder = tmp_path_factory.mktemp("exp") / "images"
    exp = render_experiment(folder, M=3, n_heldout=20, seed=1)
    return folder, exp


@pytest.fixture(scope="module")
def measured(
    experiment: tuple[Path, RenderedExperiment], tmp_path_factory: pytest.TempPathFactory
) -> Path:
    folder, _ = experiment
    out = tmp_path_factory.mktemp("out") / "measurements.json"
    assert main(["measure", str(folder), "--rig", str(folder / "rig.yaml"), "-o", str(out)]) == 0
    return out


def test_rendered_folder_layout(experiment: tuple[Path, RenderedExperiment]) -> None:
    folder, exp = experiment
    n = exp.measured.n_records
    assert n == 6 * 3 + 1
    assert (
        len(list((folder / "left").glob("*.png")))
        == n
        == len(list((folder / "right").glob("*.png")))
    )
    table = read_joints_csv(folder / "joints.csv", STRUCTURE)
    np.testing.assert_allclose(table.q, exp.measured.q, atol=1e-12)
    assert (folder / "rig.yaml").read_text().startswith("%YAML")
    assert sum(exp.hidden) == 0  # every circle visible in both cameras


def test_measured_poses_match_the_truth(
    experiment: tuple[Path, RenderedExperiment], measured: Path
) -> None:
    folder, exp = experiment
    ms = load_measurements(measured)
    exact = load_measurements(folder / "exact.json")
    assert ms.n_records == exact.n_records
    for f in ("plate_left", "plate_right"):
        assert ms.has_pose(f).all()
        d = np.linalg.norm(ms.poses[f][:, :3, 3] - exact.poses[f][:, :3, 3], axis=1)
        a = rotation_error(ms.poses[f][:, :3, :3], exact.poses[f][:, :3, :3])
        assert d.max() < 0.1e-3 and np.degrees(a.max()) < 0.1
        assert np.isfinite(ms.points[f]).all()  # the triangulated circle centres are kept
    assert ms.metadata["provenance"]["ellipse_bias_corrected"] is True


def test_identification_from_images_matches_exact_poses_with_the_same_noise(
    experiment: tuple[Path, RenderedExperiment], measured: Path
) -> None:
    folder, exp = experiment
    ms = load_measurements(measured)
    exact = load_measurements(folder / "exact.json")
    heldout = load_measurements(folder / "heldout.json")
    rig = exp.rig
    designs = robot_plate_designs(STRUCTURE.frames)
    # The detector's pixel error, measured against the truth on these very images.
    views = [
        PinholeView(rig.K1, rig.D1, rig.image_size, inverse(rig.T_world_camera(w)))
        for w in ("left", "right")
    ]
    errs = []
    for i in range(0, ms.n_records, 3):
        img = [
            cv2.imread(str(folder / s / f"{i:04d}.png"), cv2.IMREAD_GRAYSCALE)
            for s in ("left", "right")
        ]
        from cpc2urdf.identification.vision.plate_poses import stereo_plate_poses

        res = stereo_plate_poses(img[0], img[1], rig, designs)
        for d in designs:
            for v, uv in zip(views, (res[d.name].uv_left, res[d.name].uv_right), strict=True):  # type: ignore[union-attr]
                errs.append(uv - circle_centres_px(v, d, exact.poses[d.name][i]))
    sigma_px = float(np.sqrt(np.mean(np.concatenate(errs) ** 2)))
    assert sigma_px < 0.05

    def score(m: MeasurementSet) -> float:
        model, _ = identify_closed_form(m)
        return max(b.rms for b in accuracy(model, heldout).values())

    from_images = score(ms)
    reference = []
    for seed in range(5):
        rng = np.random.default_rng(seed)
        poses = {
            d.name: stereo_noise(exact.poses[d.name], d.layout, rig, sigma_px, rng)[0]
            for d in designs
        }
        reference.append(score(MeasurementSet(STRUCTURE, exact.q, poses, labels=exact.labels)))
    # As accurate as exact poses with the detector's noise (within the spread of 5 noise draws).
    assert from_images < 2.0 * float(np.median(reference)) + 2e-6, (from_images, reference)
    assert from_images < 0.1e-3  # [m] held-out positioning error


def _small_copy(folder: Path, dst: Path, n: int = 3) -> Path:
    dst.mkdir()
    for sub in ("left", "right"):
        (dst / sub).mkdir()
        for i in range(n):
            shutil.copy(folder / sub / f"{i:04d}.png", dst / sub / f"{i:04d}.png")
    lines = (folder / "joints.csv").read_text().splitlines()
    (dst / "joints.csv").write_text("\n".join(lines[: n + 1]) + "\n")
    shutil.copy(folder / "rig.yaml", dst / "rig.yaml")
    return dst


def test_broken_images_skip_or_stop(
    experiment: tuple[Path, RenderedExperiment], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder, exp = experiment
    d = _small_copy(folder, tmp_path / "imgs", n=4)
    (d / "right" / "0001.png").write_bytes(b"\x89PNG\r\n\x1a\nthis is not an image")  # corrupt
    (d / "left" / "0002.png").unlink()  # missing
    cv2.imwrite(str(d / "left" / "0003.png"), np.zeros((1024, 1280), np.uint8))  # blank
    rig = exp.rig
    view = PinholeView(rig.K1, rig.D1, rig.image_size)
    designs = robot_plate_designs(STRUCTURE.frames)
    only_left = render_view(
        view,
        [(designs[0], exp.measured.poses["plate_left"][0])],
        noise_sigma=2.0,
        rng=np.random.default_rng(0),
    )
    cv2.imwrite(str(d / "left" / "0000.png"), only_left)  # plate_right missing
    out = tmp_path / "m.json"
    args = ["measure", str(d), "--rig", str(d / "rig.yaml"), "-o", str(out)]
    assert main(args + ["--on-error", "stop"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "left/0000.png: plate_right" in err[0], err
    assert not out.exists()
    assert main(args) == 0  # skip (default)
    cap = capsys.readouterr()
    assert "skipped" in cap.out
    for needle in (
        "left/0000.png: plate_right",
        "right/0001.png",
        "not a readable image",
        "left/0002.*",
        "no image file",
        "left/0003.png",
        "blank image",
    ):
        assert needle in cap.err, needle
    ms = load_measurements(out)
    assert ms.labels == [exp.measured.labels[0]]  # only record 0 left ...
    assert (
        ms.has_pose("plate_left").all() and not ms.has_pose("plate_right").any()
    )  # ... with one plate
    assert len(ms.metadata["provenance"]["skipped"]) == 5  # the blank image: both plates
    # skip-record: record 0 lost plate_right, so it goes too -> nothing left.
    assert main(args + ["--on-error", "skip-record"]) == 2
    assert "no plate could be measured" in capsys.readouterr().err
    # Nothing measurable at all: a clear error, no file.
    for p in (d / "left").glob("*.png"):
        cv2.imwrite(str(p), np.zeros((1024, 1280), np.uint8))
    out.unlink()
    assert main(args) == 2
    assert "no plate could be measured" in capsys.readouterr().err
    assert not out.exists()


def test_bad_rig_joints_and_folders(
    experiment: tuple[Path, RenderedExperiment], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder, _ = experiment
    d = _small_copy(folder, tmp_path / "imgs", n=2)
    out = tmp_path / "m.json"

    def run(*extra: str, rig: Path | None = None) -> str:
        assert (
            main(["measure", str(d), "--rig", str(rig or d / "rig.yaml"), "-o", str(out), *extra])
            == 2
        )
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1, err
        assert not out.exists()
        return err[0]

    bad_rig = tmp_path / "rig.yaml"
    bad_rig.write_text(
        "\n".join(
            ln
            for ln in (d / "rig.yaml").read_text().splitlines()
            if not ln.startswith("D2") and "rows: 1" not in ln
        )
        + "\n"
    )
    text = (d / "rig.yaml").read_text()
    bad_rig.write_text(text.replace("T: !!opencv-matrix", "T_typo: !!opencv-matrix"))
    assert "missing key T" in run(rig=bad_rig)
    small = tmp_path / "small.yaml"
    small.write_text(text.replace("data: [ 1280, 1024 ]", "data: [ 640, 512 ]"))
    msg = run("--on-error", "stop", rig=small)
    assert "1280 x 1024 px" in msg and "640 x 512" in msg
    (d / "joints.csv").write_text("record,table_x[mm],pan[deg]\n0000,1,2\n")
    assert "missing joint column 'table_y'" in run()
    (d / "joints.csv").write_text(
        "record,table_x[deg],table_y,pan,tilt,vergence_left,vergence_right\n0000,1,2,3,4,5,6\n"
    )
    assert "unit [deg] does not fit a prismatic joint" in run()
    (d / "joints.csv").write_text(
        "record,table_x,table_y,pan,tilt,vergence_left,vergence_right,zoom\n"
    )
    assert "unknown joint column 'zoom'" in run()
    # table_x, table_y inside their limits (read before pan): only pan is wrong
    (d / "joints.csv").write_text(
        "record,table_x,table_y,pan,tilt,vergence_left,vergence_right\n0000,0.1,0.2,x,4,5,6\n"
    )
    assert "row 2 (record 0000): pan must be a number" in run()
    shutil.rmtree(d / "right")
    assert "missing sub-folder right/" in run()
    assert main(["measure", str(d), "-o", str(out)]) == 2
    assert "--rig" in capsys.readouterr().err


def test_joints_csv_round_trip(tmp_path: Path) -> None:
    q = np.array([[0.5, 0.25, 1.5, 0.5, 0.7, 0.8], [0.4, 0.2, 1.4, 0.4, 0.6, 0.9]])
    p = write_joints_csv(tmp_path / "j.csv", STRUCTURE, ["a", "b"], q, ["first", "second"])
    assert "table_x[mm]" in p.read_text() and "pan[deg]" in p.read_text()
    t = read_joints_csv(p, STRUCTURE)
    np.testing.assert_allclose(t.q, q, atol=1e-12)
    assert t.records == ["a", "b"] and t.labels == ["first", "second"]
    p.write_text(p.read_text() + "a,x,1,2,3,4,5,6\n")
    with pytest.raises(InputFileError, match="appears twice"):
        read_joints_csv(p, STRUCTURE)


@pytest.fixture(scope="module")
def head(
    experiment: tuple[Path, RenderedExperiment], tmp_path_factory: pytest.TempPathFactory
) -> Path:
    folder, _ = experiment
    out = tmp_path_factory.mktemp("head") / "head"
    render_head_experiment(out, load_model(folder / "truth.json"), n_poses=5, seed=3)
    return out


def test_stage2_from_head_camera_images(
    experiment: tuple[Path, RenderedExperiment], head: Path, tmp_path: Path
) -> None:
    folder, exp = experiment
    truth = load_model(folder / "truth.json")
    out = tmp_path / "poses"
    assert (
        main(
            [
                "measure",
                str(head),
                "--stage2",
                "--model",
                str(folder / "truth.json"),
                "-o",
                str(out),
            ]
        )
        == 0
    )
    T_base_target = np.array(
        __import__("json").loads((head / "target_truth.json").read_text())["T_base_target"]
    )
    q = read_joints_csv(head / "joints.csv", truth.structure).q
    for cam, hand in (
        ("camera_left_optical", "plate_left"),
        ("camera_right_optical", "plate_right"),
    ):
        poses = load_handeye_poses(out / f"handeye_{cam}.json")
        T_base_cam = inverse(truth.T_world_base())[None] @ truth.fk_frame(cam, q)
        truth_C = inverse(T_base_cam) @ T_base_target
        d = np.linalg.norm(poses.T_camera_target[:, :3, 3] - truth_C[:, :3, 3], axis=1)
        a = rotation_error(poses.T_camera_target[:, :3, :3], truth_C[:, :3, :3])
        assert d.max() < 0.3e-3 and np.degrees(a.max()) < 0.05, (d, np.degrees(a))
        # T_base_hand comes from the given model: closing the loop gives one T_base_target.
        T_bh = inverse(truth.T_world_base())[None] @ truth.fk_frame(hand, q)
        np.testing.assert_allclose(poses.T_base_hand, T_bh, atol=1e-9)


def test_stage2_images_put_the_cameras_into_the_model(
    experiment: tuple[Path, RenderedExperiment], head: Path
) -> None:
    from cpc2urdf.identification.handeye.head_images import stage2_observations
    from cpc2urdf.identification.handeye.stage2 import calibrate_cameras, camera_errors
    from cpc2urdf.identification.vision.measure_head import HeadCamera, measure_head_images
    from cpc2urdf.identification.vision.rig_file import load_camera

    folder, _ = experiment
    truth = load_model(folder / "truth.json")
    cams = {
        c: HeadCamera(*load_camera(head / f"{c}.yaml"))
        for c in ("camera_left_optical", "camera_right_optical")
    }
    res = measure_head_images(head, cams, truth.structure)
    model, results = calibrate_cameras(
        truth.without_frames(["camera"]), stage2_observations(res, cams), "tsai"
    )
    for c, (dt, dr) in camera_errors(model, truth, list(cams)).items():
        assert dt < 0.5e-3 and np.degrees(dr) < 0.05, (c, dt, np.degrees(dr))


def test_colour_16_bit_and_tiff_images_read_like_grey(
    experiment: tuple[Path, RenderedExperiment], tmp_path: Path
) -> None:
    from cpc2urdf.identification.vision.measure_stereo import measure_stereo_images

    folder, exp = experiment
    d = _small_copy(folder, tmp_path / "imgs", n=1)
    grey = cv2.imread(str(d / "left" / "0000.png"), cv2.IMREAD_GRAYSCALE)
    (d / "left" / "0000.png").unlink()
    cv2.imwrite(str(d / "left" / "0000.tif"), (grey.astype(np.uint16) * 257))  # 16-bit TIFF
    right = cv2.imread(str(d / "right" / "0000.png"), cv2.IMREAD_GRAYSCALE)
    cv2.imwrite(str(d / "right" / "0000.png"), cv2.cvtColor(right, cv2.COLOR_GRAY2BGR))  # colour
    res = measure_stereo_images(d, exp.rig, STRUCTURE)
    ref = load_measurements(folder / "exact.json")
    assert not res.problems
    for f in ("plate_left", "plate_right"):
        assert np.linalg.norm(res.measurements.poses[f][0, :3, 3] - ref.poses[f][0, :3, 3]) < 0.1e-3


def test_right_camera_rendered_with_its_own_intrinsics(tmp_path: Path) -> None:
    """A rig whose right camera differs from the left (focal length, centre, distortion): the
    right images are rendered with K2/D2, so measuring them with the same rig gives the true poses
    (rendering both with K1/D1 put the right circles tens of px off)."""
    import dataclasses

    from cpc2urdf.identification.vision.stereo import StereoRig

    base = StereoRig.verged()
    K2 = base.K2.copy()
    K2[0, 0] *= 1.05
    K2[1, 1] *= 1.05
    K2[0, 2] += 12.0
    rig = dataclasses.replace(base, K2=K2, D2=np.array([-0.05, 0.01, 0.0, 0.0, 0.0]))
    folder = tmp_path / "images"
    render_experiment(folder, M=2, n_heldout=1, seed=3, rig=rig, supersample=2)
    out = tmp_path / "measurements.json"
    assert main(["measure", str(folder), "--rig", str(folder / "rig.yaml"), "-o", str(out)]) == 0
    ms, exact = load_measurements(out), load_measurements(folder / "exact.json")
    for f in ("plate_left", "plate_right"):
        assert ms.has_pose(f).all()
        d = np.linalg.norm(ms.poses[f][:, :3, 3] - exact.poses[f][:, :3, 3], axis=1)
        assert d.max() < 0.2e-3
