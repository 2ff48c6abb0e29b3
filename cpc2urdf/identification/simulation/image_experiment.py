"""Whole experiments as images: simulate, render, and write the folders ``cpc2urdf measure`` reads.

:func:`render_experiment` simulates a stage-1 experiment
(:func:`~cpc2urdf.identification.simulation.stage1_experiment.simulate_experiment`, exact poses) and
renders what the stereo rig sees at every record (:mod:`~cpc2urdf.identification.vision.render`):
``left/``, ``right/``, ``joints.csv``, ``rig.yaml``, plus the truth for scoring.
:func:`render_head_experiment` does the same for stage 2: the head's cameras photograph the
25-disk target (``<camera>/``, ``joints.csv``, ``<camera>.yaml``, ``target_truth.json``). So the
whole pipeline -- detection, measurement, identification, hand-eye -- can run from rendered
pixels (``docs/images.md``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import ConfigurationError, OutputError
from cpc2urdf.files.jsonio import write_json
from cpc2urdf.files.measurements import MeasurementSet, save_measurements
from cpc2urdf.files.model_file import save_model
from cpc2urdf.files.robot_ref import load_robot
from cpc2urdf.files.spec import RobotSpec
from cpc2urdf.identification.handeye import stage2
from cpc2urdf.identification.handeye.stage2 import CameraIntrinsics
from cpc2urdf.identification.simulation.placement import clear_placement
from cpc2urdf.identification.simulation.stage1_experiment import simulate_experiment
from cpc2urdf.identification.simulation.visibility import board_in_view, check_view
from cpc2urdf.identification.vision.boards.board import Board
from cpc2urdf.identification.vision.image_folders import write_image
from cpc2urdf.identification.vision.joints_csv import write_joints_csv
from cpc2urdf.identification.vision.measure_stereo import STEREO_FOLDERS
from cpc2urdf.identification.vision.render import (
    PinholeView,
    hidden_circles,
    render_board_view,
    render_view,
)
from cpc2urdf.identification.vision.rig_file import save_camera, save_rig
from cpc2urdf.identification.vision.stereo import StereoRig
from cpc2urdf.identification.vision.targets import PlateDesign, robot_plate_designs, target_design
from cpc2urdf.model import CPCModel, CPCParams
from cpc2urdf.progress import progress
from cpc2urdf.transforms import homogeneous, inverse

Array = NDArray[np.float64]


@dataclass
class RenderedExperiment:
    """What :func:`render_experiment` wrote and simulated.

    Attributes:
        folder: The images folder.
        truth: The true robot (placed in the rig's world).
        measured: The exact (noise-free) plate poses of the rendered records.
        heldout: Held-out configurations with true poses.
        rig: The rig.
        paths: Written files by role (``rig``, ``joints``, ``truth``, ``heldout``, ``exact``).
        hidden: Per record, the number of circles hidden (occluded/at the border) in either image.
    """

    folder: Path
    truth: CPCModel
    measured: MeasurementSet
    heldout: MeasurementSet
    rig: StereoRig
    paths: dict[str, Path]
    hidden: list[int]


def clear_image_placement(
    spec: RobotSpec, rig: StereoRig, q: Array, designs: Sequence[PlateDesign]
) -> CPCParams:
    """A ``world_to_base`` (CPC constants) that shows both cameras every circle of every plate.

    The simulator's search (:func:`cpc2urdf.identification.simulation.placement.clear_placement`) for the
    nominal robot of ``spec`` over configurations ``q`` (N, n) with the plate outlines of
    ``designs``; raises ``ConfigurationError`` when no candidate keeps every plate in view.
    """
    nominal = spec.nominal_model()
    frames = [d.name for d in designs]
    w2b = clear_placement(nominal, rig, q, frames, designs=designs)
    view = check_view(
        nominal.with_params(world_to_base=w2b),
        rig,
        q,
        frames,
        [str(i) for i in range(len(q))],
        designs=designs,
    )
    if view.unseen:
        raise ConfigurationError("no placement of the robot lets both rig cameras see every plate")
    return w2b


def render_experiment(
    folder: str | Path,
    robot: str = "iis_head",
    *,
    seed: int = 0,
    M: int = 9,
    n_heldout: int = 50,
    rig: StereoRig | None = None,
    blur_sigma: float = 0.7,
    noise_sigma: float = 2.0,
    supersample: int = 8,
    show_progress: bool = False,
) -> RenderedExperiment:
    """Simulate a stage-1 experiment and write it as images (the input of ``cpc2urdf measure``).

    Writes ``folder/left/<record>.png``, ``folder/right/<record>.png``, ``folder/joints.csv``
    (mm/deg), ``folder/rig.yaml`` (mm), and for scoring ``folder/truth.json`` (the true model),
    ``folder/heldout.json`` and ``folder/exact.json`` (the true poses of the rendered records).

    Args:
        folder: Output folder (created if missing; its parent must exist).
        robot: Shipped robot name or spec path.
        seed: Seed of the true robot's geometric errors and of the image noise.
        M: Values per joint (one-joint-at-a-time protocol, n M + 1 records).
        n_heldout: Held-out configurations (true poses, not rendered).
        rig: The stereo rig (default the paper's: 600 mm baseline, 1.5 m).
        blur_sigma: Optical blur [px].
        noise_sigma: Grey-level noise [of 255].
        supersample: Anti-aliasing sub-samples per axis.
        show_progress: Progress bar on stderr.
    """
    out, spec, rig = _experiment_inputs(folder, robot, rig)
    s = spec.structure
    designs = robot_plate_designs(s.frames)
    # The simulator's default placement: no circle hidden over the protocol and the held-out box.
    truth, exact, heldout = simulate_experiment(
        spec, seed=seed, M=M, noise="none", n_heldout=n_heldout, rig=rig, robot_ref=robot
    )
    views = [
        PinholeView(
            K, D, rig.image_size, np.asarray(np.linalg.inv(rig.T_world_camera(w)), dtype=np.float64)
        )
        for w, K, D in zip(STEREO_FOLDERS, (rig.K1, rig.K2), (rig.D1, rig.D2), strict=True)
    ]
    fk = truth.fk(exact.q, [d.name for d in designs])

    def plates(i: int) -> list[tuple[PlateDesign, Array]]:
        return [(d, fk[d.name][i]) for d in designs]

    def image(v: PinholeView, i: int, rng: np.random.Generator) -> NDArray[np.uint8]:
        return render_view(
            v,
            plates(i),
            blur_sigma=blur_sigma,
            noise_sigma=noise_sigma,
            rng=rng,
            supersample=supersample,
        )

    return _write_experiment(
        out, truth, exact, heldout, rig, views, seed, plates, image, show_progress
    )


def render_head_experiment(
    folder: str | Path,
    truth: CPCModel,
    *,
    n_poses: int = 12,
    seed: int = 0,
    intrinsics: CameraIntrinsics | None = None,
    blur_sigma: float = 0.7,
    noise_sigma: float = 2.0,
) -> dict[str, Path]:
    """Simulate stage 2 and write it as images: the head's cameras (their frames in ``truth``)
    photograph the 25-disk target from ``n_poses`` random configurations.

    Writes ``folder/<camera>/<record>.png`` for both camera frames, ``folder/joints.csv``,
    ``folder/<camera>.yaml`` (intrinsics, OpenCV FileStorage) and ``folder/target_truth.json``
    (the true ``T_base_target``).

    Returns:
        Written files by role.
    """
    out = _output_folder(folder)
    intr = intrinsics or stage2.DEFAULT_INTRINSICS
    cameras = list(stage2.HAND_OF_CAMERA)
    rng = np.random.default_rng(seed)
    T_base_target = stage2.default_target_placement(truth, cameras)
    q = stage2.sample_configurations(
        truth, n_poses, rng, T_base_target, cameras=cameras, intrinsics=intr
    )
    design = target_design()
    T_world_target = truth.T_world_base() @ T_base_target

    def image(view: PinholeView) -> NDArray[np.uint8]:
        return render_view(
            view,
            [(design, T_world_target)],
            blur_sigma=blur_sigma,
            noise_sigma=noise_sigma,
            rng=rng,
        )

    return _write_head_images(out, truth, intr, cameras, q, T_base_target, image, "target")


# ---- standard boards: calibration views and stage-2 board images -------------------------------------


def _board_in_view(
    view: PinholeView, board: Board, T_world_board: Array, margin_px: float = 10.0
) -> bool:
    """The whole board (outline) in front of the camera, inside the image by ``margin_px``, face towards it."""
    return bool(
        board_in_view(view, board, view.T_camera_world @ T_world_board, margin_px=margin_px)[0]
    )


def random_board_poses(
    views: Sequence[PinholeView],
    board: Board,
    n: int,
    rng: np.random.Generator,
    *,
    distance: tuple[float, float],
    max_tilt_deg: float = 35.0,
) -> Array:
    """``n`` random ``T_world_board`` that every camera of ``views`` sees whole (:func:`_board_in_view`):
    the board centre on a ray of the first camera at ``distance`` (min, max) [m], facing it,
    tilted by up to ``max_tilt_deg`` about a random in-plane axis and rolled at random.

    Raises:
        ConfigurationError: Fewer than ``n`` such poses in ``500 n`` draws (board too large).
    """
    from scipy.spatial.transform import Rotation

    T_world_cam0 = inverse(views[0].T_camera_world)
    out: list[Array] = []
    for _ in range(500 * n):
        if len(out) == n:
            break
        d = rng.uniform(*distance)
        ray = np.array([rng.uniform(-0.25, 0.25), rng.uniform(-0.2, 0.2), 1.0])
        axis = np.array([*rng.normal(size=2), 0.0])
        tilt = Rotation.from_rotvec(
            np.radians(rng.uniform(0, max_tilt_deg)) * axis / np.linalg.norm(axis)
        ).as_matrix()
        roll = Rotation.from_euler("z", rng.uniform(-180, 180), degrees=True).as_matrix()
        R_cam_board = (
            tilt @ np.diag([1.0, -1.0, -1.0]) @ roll
        )  # board z towards the camera, then tilted
        T = T_world_cam0 @ homogeneous(R_cam_board, d * ray / ray[2])
        if all(_board_in_view(v, board, T) for v in views):
            out.append(T)
    if len(out) < n:
        raise ConfigurationError(
            f"{board.name}: only {len(out)} of {n} random poses keep the whole board in view; "
            "use a smaller board or a larger distance"
        )
    return np.array(out)


def render_board_calibration(
    folder: str | Path,
    board: Board,
    *,
    camera: CameraIntrinsics | None = None,
    rig: StereoRig | None = None,
    n_views: int = 12,
    seed: int = 0,
    distance: tuple[float, float] | None = None,
    blur_sigma: float = 0.7,
    noise_sigma: float = 2.0,
) -> Array:
    """Write views of ``board`` for ``cpc2urdf calibrate``: one camera (``folder/<view>.png``,
    default the stage-2 head camera) or, with ``rig``, a stereo rig (``folder/left``,
    ``folder/right``). Returns the true ``T_world_board`` (world = the (left) camera), shape
    (n_views, 4, 4); ``folder/board_truth.json`` holds them and the true camera(s)."""
    out = _output_folder(folder)
    rng = np.random.default_rng(seed)
    if rig is not None:
        views = [
            PinholeView(
                K, D, rig.image_size, np.asarray(inverse(rig.T_world_camera(w)), dtype=np.float64)
            )
            for w, K, D in (("left", rig.K1, rig.D1), ("right", rig.K2, rig.D2))
        ]
        subs = [out / "left", out / "right"]
        distance = distance or (1.2, 1.8)
    else:
        intr = camera or stage2.DEFAULT_INTRINSICS
        views = [PinholeView(intr.K, intr.D, (intr.width, intr.height), np.eye(4))]
        subs = [out]
        distance = distance or (0.35, 0.6)
    T = random_board_poses(views, board, n_views, rng, distance=distance)
    for sub, view in zip(subs, views, strict=True):
        sub.mkdir(parents=True, exist_ok=True)
        for i in range(n_views):
            img = render_board_view(
                view, [(board, T[i])], blur_sigma=blur_sigma, noise_sigma=noise_sigma, rng=rng
            )
            write_image(sub / f"{i:04d}.png", img)
    truth: dict[str, object] = {
        "description": "true board poses (world = the (left) camera) and cameras, for scoring",
        "board": board.to_json(),
        "T_world_board": T.tolist(),
        "units": {"length": "m"},
    }
    truth.update(
        {"rig": rig.to_json()}
        if rig is not None
        else {
            "K": views[0].K.tolist(),
            "D": np.asarray(views[0].D, dtype=float).tolist(),
            "image_size": list(views[0].image_size),
        }
    )
    write_json(out / "board_truth.json", truth)
    return T


def render_head_board_experiment(
    folder: str | Path,
    truth: CPCModel,
    board: Board,
    *,
    n_poses: int = 12,
    seed: int = 0,
    intrinsics: CameraIntrinsics | None = None,
    blur_sigma: float = 0.7,
    noise_sigma: float = 2.0,
) -> dict[str, Path]:
    """:func:`render_head_experiment` with a standard board as the stage-2 target: the same files
    (``<camera>/``, ``<camera>.yaml``, ``joints.csv``, ``target_truth.json``); configurations are
    drawn as there and kept when both cameras see the whole board."""
    out = _output_folder(folder)
    intr = intrinsics or stage2.DEFAULT_INTRINSICS
    cameras = list(stage2.HAND_OF_CAMERA)
    rng = np.random.default_rng(seed)
    T_base_target = stage2.default_target_placement(truth, cameras)
    T_world_target = truth.T_world_base() @ T_base_target
    size = (intr.width, intr.height)
    q: list[Array] = []
    for _ in range(200 * n_poses):
        if len(q) == n_poses:
            break
        qi = stage2.sample_configurations(
            truth, 1, rng, T_base_target, cameras=cameras, intrinsics=intr
        )[0]
        if all(
            _board_in_view(
                PinholeView(intr.K, intr.D, size, inverse(truth.fk_frame(c, qi[None])[0])),
                board,
                T_world_target,
            )
            for c in cameras
        ):
            q.append(qi)
    if len(q) < n_poses:
        raise ConfigurationError(
            f"{board.name}: only {len(q)} of {n_poses} configurations show both cameras the whole board"
        )

    def image(view: PinholeView) -> NDArray[np.uint8]:
        return render_board_view(
            view, [(board, T_world_target)], blur_sigma=blur_sigma, noise_sigma=noise_sigma, rng=rng
        )

    return _write_head_images(out, truth, intr, cameras, np.array(q), T_base_target, image, "board")


def _write_head_images(
    out: Path,
    truth: CPCModel,
    intr: CameraIntrinsics,
    cameras: Sequence[str],
    q: Array,
    T_base_target: Array,
    image: Callable[[PinholeView], NDArray[np.uint8]],
    target: str,
) -> dict[str, Path]:
    """Write a simulated stage-2 folder: :func:`write_camera_images` with the same image for
    every record at a view, then ``target_truth.json`` (the true ``T_base_target``; ``target``
    names it). Returns the written files by role."""
    paths = write_camera_images(out, truth, dict.fromkeys(cameras, intr), q, lambda v, _: image(v))
    paths["target_truth"] = write_json(
        out / "target_truth.json",
        {
            "description": f"true pose of the stage-2 {target} in the robot base frame (for scoring)",
            "T_base_target": T_base_target.tolist(),
            "units": {"length": "m"},
        },
    )
    return paths


def write_camera_images(
    out: Path,
    model: CPCModel,
    intrinsics: Mapping[str, CameraIntrinsics],
    q: Array,
    image: Callable[[PinholeView, int], NDArray[np.uint8]],
    *,
    show_progress: bool = False,
    folders: Mapping[str, str] | None = None,
) -> dict[str, Path]:
    """Write what a robot's own cameras see, in the layout ``measure_head`` reads: per camera
    frame of ``model`` (the keys of ``intrinsics``, in order) ``<camera>.yaml`` and, at each
    configuration ``q[i]``, ``image(view, i)`` as ``<camera>/<record>.png`` (records ``0000``,
    ``0001``, ...; cameras outer, records inner), ``<camera>`` the frame's name in ``folders``
    (default the frame's own); then ``joints.csv``. Returns the written files by role (camera
    frame -> its ``.yaml``, ``joints``)."""
    records = [f"{i:04d}" for i in range(len(q))]
    paths: dict[str, Path] = {}
    jobs = [(c, i) for c in intrinsics for i in range(len(q))]
    T_world_cam = {c: model.fk_frame(c, q).reshape(-1, 4, 4) for c in intrinsics}
    name = {c: (folders or {}).get(c, c) for c in intrinsics}
    for c, intr in intrinsics.items():
        (out / name[c]).mkdir(parents=True, exist_ok=True)
        size = (intr.width, intr.height)
        paths[c] = save_camera(intr.K, intr.D, size, out / f"{name[c]}.yaml")
    for c, i in progress(jobs, "render") if show_progress else jobs:
        intr = intrinsics[c]
        view = PinholeView(intr.K, intr.D, (intr.width, intr.height), inverse(T_world_cam[c][i]))
        write_image(out / name[c] / f"{records[i]}.png", image(view, i))
    paths["joints"] = write_joints_csv(out / "joints.csv", model.structure, records, q)
    return paths


def _output_folder(folder: str | Path) -> Path:
    """``folder`` as a path, its parent required to exist."""
    out = Path(folder)
    if not out.parent.is_dir():
        raise OutputError(f"{out}: parent folder {out.parent} does not exist")
    return out


def board_proxy_designs(boards: Mapping[str, Board]) -> list[PlateDesign]:
    """Boards as :class:`PlateDesign` outlines for the placement search and the occlusion tests:
    their detectable points as the "circles" (radius a quarter of the point spacing)."""
    return [
        PlateDesign(
            frame, b.object_points(), np.full(b.n_points, 0.25 * b.point_spacing), b.outline
        )
        for frame, b in boards.items()
    ]


def render_board_experiment(
    folder: str | Path,
    boards: Mapping[str, Board],
    robot: str = "iis_head",
    *,
    seed: int = 0,
    M: int = 9,
    n_heldout: int = 50,
    rig: StereoRig | None = None,
    blur_sigma: float = 0.7,
    noise_sigma: float = 2.0,
    supersample: int = 6,
    only: Sequence[int] | None = None,
    show_progress: bool = False,
) -> RenderedExperiment:
    """:func:`render_experiment` with standard boards as the stage-1 plates (plate frame -> board,
    the board frame being the plate frame): the same files, the same true robot for a seed; the
    robot is placed (:func:`~cpc2urdf.identification.simulation.placement.clear_placement`) so
    that no board hides another's corners over the protocol. ``hidden`` counts, per record, the
    board corners hidden in either image (:func:`~cpc2urdf.identification.vision.render.hidden_circles`
    on the boards' outlines). ``only``: render (and list in ``joints.csv``) only these records of the
    protocol, for quick tests; ``measured`` and ``exact.json`` then hold those records too."""
    out, spec, rig = _experiment_inputs(folder, robot, rig)
    s = spec.structure
    proxies = board_proxy_designs(boards)
    frames = [d.name for d in proxies]
    first = simulate_experiment(
        spec, seed=seed, M=M, noise="none", n_heldout=1, rig=rig, robot_ref=robot
    )[1]
    w2b = clear_placement(spec.nominal_model(), rig, first.q, frames, designs=proxies)
    truth, exact, heldout = simulate_experiment(
        spec,
        seed=seed,
        M=M,
        noise="none",
        n_heldout=n_heldout,
        rig=rig,
        robot_ref=robot,
        world_to_base=w2b,
        require_view=False,
    )
    if only is not None:
        keep = np.asarray(only, dtype=int)
        exact = MeasurementSet(
            s,
            exact.q[keep],
            {f: P[keep] for f, P in exact.poses.items()},
            exact.source,
            exact.robot,
            [exact.labels[i] for i in keep],
            metadata=exact.metadata,
        )
    views = [
        PinholeView(
            K, D, rig.image_size, np.asarray(np.linalg.inv(rig.T_world_camera(w)), dtype=np.float64)
        )
        for w, K, D in (("left", rig.K1, rig.D1), ("right", rig.K2, rig.D2))
    ]
    fk = truth.fk(exact.q, frames)

    def outlines(i: int) -> list[tuple[PlateDesign, Array]]:
        return [(d, fk[d.name][i]) for d in proxies]

    def image(v: PinholeView, i: int, rng: np.random.Generator) -> NDArray[np.uint8]:
        placed = [(b, fk[frame][i]) for frame, b in boards.items()]
        return render_board_view(
            v,
            placed,
            blur_sigma=blur_sigma,
            noise_sigma=noise_sigma,
            rng=rng,
            supersample=supersample,
        )

    return _write_experiment(
        out, truth, exact, heldout, rig, views, seed, outlines, image, show_progress
    )


def _experiment_inputs(
    folder: str | Path, robot: str, rig: StereoRig | None
) -> tuple[Path, RobotSpec, StereoRig]:
    """The output folder (its parent must exist), the robot and the rig (default the paper's)."""
    out = _output_folder(folder)
    return out, load_robot(robot), rig or StereoRig.verged()


def _write_experiment(
    out: Path,
    truth: CPCModel,
    exact: MeasurementSet,
    heldout: MeasurementSet,
    rig: StereoRig,
    views: Sequence[PinholeView],
    seed: int,
    outlines: Callable[[int], list[tuple[PlateDesign, Array]]],
    image: Callable[[PinholeView, int, np.random.Generator], NDArray[np.uint8]],
    show_progress: bool,
) -> RenderedExperiment:
    """Write a simulated stereo experiment's folder: per record, ``image(view, record, rng)`` in
    ``left/`` and ``right/`` (``views`` in :data:`STEREO_FOLDERS` order, the image noise drawn from
    the seed's fourth stream), the circles of ``outlines(record)`` hidden in either view counted,
    then ``joints.csv``, ``rig.yaml`` and the truth files."""
    for sub in STEREO_FOLDERS:
        (out / sub).mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(4)[3])
    records = [f"{i:04d}" for i in range(exact.n_records)]
    hidden = []
    items = progress(range(exact.n_records), "render") if show_progress else range(exact.n_records)
    for i in items:
        hidden.append(sum(sum(hidden_circles(v, outlines(i)).values()) for v in views))
        for sub, v in zip(STEREO_FOLDERS, views, strict=True):
            write_image(out / sub / f"{records[i]}.png", image(v, i, rng))
    paths = {
        "joints": write_joints_csv(
            out / "joints.csv", exact.structure, records, exact.q, exact.labels
        ),
        "rig": save_rig(rig, out / "rig.yaml", units="mm"),
        "truth": save_model(truth, out / "truth.json"),
        "heldout": save_measurements(heldout, out / "heldout.json"),
        "exact": save_measurements(exact, out / "exact.json"),
    }
    return RenderedExperiment(out, truth, exact, heldout, rig, paths, hidden)


__all__ = [
    "RenderedExperiment",
    "board_proxy_designs",
    "clear_image_placement",
    "random_board_poses",
    "render_board_calibration",
    "render_board_experiment",
    "render_experiment",
    "render_head_board_experiment",
    "render_head_experiment",
    "write_camera_images",
]
