"""``cpc2urdf demo``: the whole pipeline on the built-in IIS-head example.

Each stage runs the same command a user would type (through :func:`cpc2urdf.cli.main`), writes
its artefacts into the output folder, and the demo stops at the first stage that fails:

1. nominal IIS-head (Shih et al. Tables 2-3) -> URDF -> three-parser cross-check;
2. ``simulate``: a "true" head (nominal + geometric errors, camera mounts off by mm and degrees)
   measured by a stereo rig, one joint at a time (sec. 4.1), plus held-out configurations;
3. ``identify`` (closed form + maximum-likelihood refinement) -> ``export`` -> ``check``;
4. ``accuracy``: the paper's Table 4 on the held-out configurations;
5. stage 2: the head's cameras view a 5x5 disk target, solvePnP, hand-eye (the joint nonlinear
   refinement of AX = ZB; ``handeye --method all`` shows Tsai, the paper's choice, and the others
   side by side) -> calibrated model with camera frames -> ``export`` -> ``check``;
6. ``gaze``: fixate targets with the calibrated head (its head report after ``check``);
7. ``view``: a self-contained meshcat page of the calibrated head fixating a target;
8. ``reach``: where the calibrated head can point its eyes, as slices (PNG) and in the 3D view.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from cpc2urdf.model import CPCModel
    from cpc2urdf.transforms import Array


def add_parser(subparsers: argparse._SubParsersAction) -> None:  # type: ignore[type-arg]
    p = subparsers.add_parser(
        "demo",
        help="run the pipeline on the built-in IIS-head example",
        description="Run the pipeline on the built-in IIS-head example (simulate -> identify -> "
        "export -> check -> accuracy -> hand-eye -> gaze -> view -> reach) and write every artefact into "
        "the output folder.",
    )
    p.add_argument("-o", "--output", default="demo-out", help="output folder (default: demo-out)")
    p.add_argument("--seed", type=int, default=0, help="seed of every random step (default 0)")
    p.add_argument(
        "--from-images",
        action="store_true",
        help="render the stereo-rig and head-camera images and measure them with the circle "
        "detector (stages 2 and 5), instead of simulating poses (about a minute longer)",
    )
    p.set_defaults(run=run)


class _Stages:
    def __init__(self) -> None:
        self.k = 0
        self.t = time.perf_counter()

    def start(self, title: str) -> None:
        self.k += 1
        self.t = time.perf_counter()
        print(f"\n== {self.k}. {title}", flush=True)

    def done(self) -> None:
        print(f"   ({time.perf_counter() - self.t:.1f} s)", flush=True)


def _cli(*argv: str, ok: tuple[int, ...] = (0,)) -> None:
    from cpc2urdf.cli import main
    from cpc2urdf.errors import Cpc2UrdfError

    print("$ cpc2urdf " + " ".join(argv), flush=True)
    code = main(list(argv))
    if code not in ok:
        raise Cpc2UrdfError(f"demo stage 'cpc2urdf {' '.join(argv)}' ended with exit code {code}")


def _target_ahead(model: CPCModel, distance: float = 0.6) -> tuple[Array, Array]:
    """The middle of the calibration ranges, and the point ``distance`` [m] straight ahead of the
    cameras there (world)."""
    import numpy as np

    s = model.structure
    q = s.calibration_ranges().mean(axis=1)
    fk = model.fk(q, ["camera_left_optical", "camera_right_optical"])
    L, R = fk["camera_left_optical"], fk["camera_right_optical"]
    ahead = L[:3, 2] + R[:3, 2]
    return q, (L[:3, 3] + R[:3, 3]) / 2 + distance * ahead / np.linalg.norm(ahead)


def _camera_errors(model: CPCModel, truth: CPCModel) -> str:
    from cpc2urdf.identification.handeye.stage2 import HAND_OF_CAMERA, camera_errors

    errs = camera_errors(model, truth, tuple(HAND_OF_CAMERA))
    return "\n".join(
        f"{c}: X = T_{HAND_OF_CAMERA[c]}_{c} error vs truth {t * 1e3:.3f} mm / {r * 57.29577951308232:.4f} deg"
        for c, (t, r) in errs.items()
    )


def _stage1(args: argparse.Namespace, out: Path, st: _Stages) -> tuple[CPCModel, str, str]:
    """Stage 1 simulated (or rendered and measured): the true head, the measurement and held-out files."""
    import numpy as np

    from cpc2urdf.files.model_file import save_model
    from cpc2urdf.files.robot_ref import load_model
    from cpc2urdf.identification.handeye.stage2 import perturb_cameras

    d, seed = str(out), str(args.seed)
    if args.from_images:
        st.start(
            "render the stage-1 experiment as stereo images, then measure them (circle detector)"
        )
        from cpc2urdf.identification.simulation.image_experiment import render_experiment

        exp = render_experiment(out / "images", seed=args.seed, show_progress=True)
        truth = perturb_cameras(exp.truth, np.random.default_rng(args.seed))
        save_model(truth, f"{d}/images/truth.json")
        _cli(
            "measure",
            f"{d}/images",
            "--rig",
            f"{d}/images/rig.yaml",
            "-o",
            f"{d}/measurements.json",
        )
        measurements, heldout = f"{d}/measurements.json", f"{d}/images/heldout.json"
    else:
        st.start(
            "simulate the stage-1 experiment: stereo rig measures both plates, one joint at a time"
        )
        _cli("simulate", "iis_head", "-o", f"{d}/sim", "--seed", seed)
        # The simulated real head's camera mounts differ from the drawing by millimetres and
        # degrees; stage 2 has to find them.
        truth = perturb_cameras(load_model(f"{d}/sim/truth.json"), np.random.default_rng(args.seed))
        save_model(truth, f"{d}/sim/truth.json")
        measurements, heldout = f"{d}/sim/measurements.json", f"{d}/sim/heldout.json"
    st.done()

    return truth, measurements, heldout


def _stage2(args: argparse.Namespace, out: Path, truth: CPCModel, st: _Stages) -> None:
    """Stage 2: both cameras by hand-eye calibration (from rendered images with --from-images),
    then the calibrated model's URDF, checked."""
    from cpc2urdf.files.model_file import save_model
    from cpc2urdf.files.robot_ref import load_model
    from cpc2urdf.identification.handeye.stage2 import run_stage2, write_pose_files

    d = str(out)
    if args.from_images:
        st.start(
            "stage 2 from images: the head cameras photograph the 5x5 disk target; solvePnP; hand-eye"
        )
        from cpc2urdf.identification.simulation.image_experiment import render_head_experiment

        render_head_experiment(out / "head", truth, seed=args.seed)
        _cli(
            "measure",
            f"{d}/head",
            "--stage2",
            "--model",
            f"{d}/stage1_model.json",
            "-o",
            f"{d}/handeye",
        )
        _cli(
            "handeye",
            f"{d}/handeye/handeye_camera_left_optical.json",
            "--method",
            "refined",
            "--model",
            f"{d}/stage1_model.json",
            "-o",
            f"{d}/model.json",
        )
        _cli(
            "handeye",
            f"{d}/handeye/handeye_camera_right_optical.json",
            "--method",
            "refined",
            "--model",
            f"{d}/model.json",
            "-o",
            f"{d}/model.json",
        )
        print(_camera_errors(load_model(f"{d}/model.json"), truth))
    else:
        st.start(
            "stage 2: hand-eye calibration of both cameras (5x5 disk target, solvePnP, AX = ZB refined)"
        )
        result = run_stage2(
            load_model(f"{d}/stage1_model.json"), truth, seed=args.seed, method="refined"
        )
        print(result.summary())
        paths = write_pose_files(result, out)
        save_model(result.model, f"{d}/model.json")
        _cli("handeye", str(paths["camera_left_optical"]), "--method", "all")
    _cli("export", f"{d}/model.json", "-o", f"{d}/head.urdf")
    _cli("check", f"{d}/head.urdf", "--model", f"{d}/model.json", "--gaze-report")
    st.done()


def _gaze(args: argparse.Namespace, out: Path, st: _Stages) -> tuple[Array, Array]:
    """Gaze on the calibrated head: a target where its axes meet, and one straight ahead. Returns
    the home readings and the target drawn in the view."""
    from cpc2urdf.files.robot_ref import load_model

    d = str(out)
    st.start("gaze: fixate targets in front of the calibrated head (joint limits as constraints)")
    from cpc2urdf.errors import DegenerateDataError
    from cpc2urdf.identification.simulation.heads import reachable_targets

    model = load_model(f"{d}/model.json")
    q_home, ahead = _target_ahead(model)
    home = [repr(float(v)) for v in q_home]
    try:
        reachable = reachable_targets(model, 1, seed=args.seed)[0][0]
    except DegenerateDataError as e:
        print(f"   no target found where this head's two optical axes meet exactly: {e}")
        reachable = ahead
    else:
        print(
            "   a target where this calibrated head's two optical axes can meet (found from its FK), with the\n"
            "   min-motion policy, which keeps an exact fixation where one exists:"
        )
        _cli(
            "gaze",
            f"{d}/model.json",
            "--target",
            *(repr(float(v)) for v in reachable),
            "--q-current",
            *home,
            "--policy",
            "min-motion",
            ok=(0, 1),
        )
    print("   a target 0.6 m straight ahead of the cameras:")
    _cli(
        "gaze",
        f"{d}/model.json",
        "--target",
        *(repr(float(v)) for v in ahead),
        "--q-current",
        *home,
        ok=(0, 1),
    )
    print(
        "   (a calibrated head whose two eyes do not sweep exactly one plane can make both optical\n"
        "    axes meet only on a thin set of targets. The default policy, cyclopean, answers every\n"
        "    target with the neck facing it and the error the head cannot remove split between the\n"
        "    eyes: status disparity, exit code 1, even where an exact fixation exists with the neck\n"
        "    turned away; docs/gaze.md)"
    )
    st.done()

    return q_home, reachable


def _view_and_reach(
    args: argparse.Namespace, out: Path, q_home: Array, reachable: Array, st: _Stages
) -> None:
    """The 3D view of the calibrated head (the truth as a ghost) and its reachable region."""
    from cpc2urdf.files.robot_ref import load_model

    d = str(out)
    model = load_model(f"{d}/model.json")
    st.start("view: a self-contained meshcat page of the calibrated head, the true head as a ghost")
    from cpc2urdf.validation.view import find_chromium, screenshot_html, write_view_html

    truth_path = f"{d}/images/truth.json" if args.from_images else f"{d}/sim/truth.json"
    summary = write_view_html(
        out / "view.html", model, target=reachable, q=q_home, ghost=truth_path
    )
    print(summary.format())
    print(f"   wrote {out / 'view.html'} (open it in a browser)")
    if find_chromium():
        screenshot_html(out / "view.html", out / "view.png")
        print(f"   wrote {out / 'view.png'} (headless Chromium screenshot)")
    st.done()

    st.start(
        "reach: where the calibrated head can point its eyes (slices as PNG, and in the 3D view)"
    )
    shot = ["--screenshot", f"{d}/reach_view.png"] if find_chromium() else []
    _cli("reach", f"{d}/model.json", "-o", f"{d}/reach.png", "--html", f"{d}/reach.html", *shot)
    print(
        "   (disparity: pointed at with the head facing the target, each eye off by the vertical\n"
        "    disparity of this calibrated head; joint limits: the tilt or pan range stops it)"
    )
    st.done()


def run(args: argparse.Namespace) -> int:

    from cpc2urdf.errors import ConfigurationError
    from cpc2urdf.files.jsonio import make_folder

    if args.seed < 0:  # numpy's generators take seeds >= 0; refused before the folder is made
        raise ConfigurationError(f"--seed must be >= 0, got {args.seed}")
    out = Path(args.output)
    make_folder(out)
    d = str(out)
    st = _Stages()

    st.start("nominal IIS-head -> URDF -> cross-check (Pinocchio, yourdfpy, urdfdom)")
    _cli("export", "iis_head", "-o", f"{d}/nominal.urdf")
    _cli("check", f"{d}/nominal.urdf", "--model", "iis_head")
    st.done()

    truth, measurements, heldout = _stage1(args, out, st)
    st.start("identify (closed form + maximum likelihood) -> URDF -> cross-check")
    _cli("identify", measurements, "-o", f"{d}/stage1_model.json")
    _cli("export", f"{d}/stage1_model.json", "-o", f"{d}/stage1.urdf")
    _cli("check", f"{d}/stage1.urdf", "--model", f"{d}/stage1_model.json")
    st.done()

    st.start("held-out accuracy (Shih et al. Table 4)")
    _cli("accuracy", f"{d}/stage1_model.json", heldout)
    st.done()

    _stage2(args, out, truth, st)
    q_home, reachable = _gaze(args, out, st)
    _view_and_reach(args, out, q_home, reachable, st)
    print(f"\ndemo finished: the calibrated head is {d}/model.json and {d}/head.urdf")
    return 0
