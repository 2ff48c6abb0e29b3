"""Study: the default hand-eye solver on KinHEC's tracks, against KinHEC's own baselines.

KinHEC (``pip install kinhec``) is a public benchmark of hand-eye and robot-world calibration:
time-stamped robot and camera streams of real arm models, tracks that vary noise, motion
degeneracy, clock offset, outliers, unknown monocular scale, robot model error and PnP image
noise, and reference solvers run by a fixed protocol (``kinhec benchmark``)::

    kinhec generate --tier small --out DATA      # 562 sequences, ~4 min on 2 cores
    kinhec benchmark DATA                        # the baselines: DATA/benchmarks/results.csv
    cpc2urdf study kinhec DATA [--tracks noise outliers] [--out ours.csv]

Every sequence goes through what ``cpc2urdf handeye ROBOT.csv CAMERA.csv`` does with its
defaults: the two measured streams are paired by
:func:`~cpc2urdf.identification.handeye.streams.pair_streams` (row by row when synchronous; the
clock offset estimated by us otherwise, never KinHEC's ground truth), KinHEC's keyframes (5 deg
or 2 cm apart, at most 200) are kept, and the default solver runs through the consistency gate.
What a user knows of their setup is passed as they would: ``--eye-to-hand`` for eye-to-hand
sequences, ``--unknown-scale`` for camera trajectories known up to scale (monocular visual
odometry: KinHEC's ``scale`` is not 1). A refusal counts as no answer, with its cause.

The table: per track, the median X rotation [deg] and translation [mm] errors of ours and of the
best baseline per metric (the lowest median of any KinHEC solver; synchronous sequences and the
temporal track with KinHEC's own offset estimate, ``estimated``, as ours is estimated too), the
ratios, the refusals, and the sequences we refuse although a baseline solves them within twice
that baseline's median error.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from cpc2urdf.argparsing import OneLineParser
from cpc2urdf.errors import Cpc2UrdfError
from cpc2urdf.transforms import Array, inverse, rotation_error


def _errors(T: Array, T_true: Array) -> tuple[float, float]:
    """Rotation [deg] and translation [mm] error, KinHEC's metric."""
    angle = float(np.degrees(rotation_error(T[:3, :3], T_true[:3, :3])))
    return angle, 1e3 * float(np.linalg.norm(T[:3, 3] - T_true[:3, 3]))


def evaluate(seq: Any) -> dict[str, Any]:
    """Our default on one KinHEC sequence: errors of X and Z, or the refusal."""
    from cpc2urdf.identification.handeye.solvers import DEFAULT_HANDEYE_METHOD, Gate, calibrate
    from cpc2urdf.identification.handeye.streams import PoseStream, pair_streams

    m = seq.manifest
    eye_to_hand = m["configuration"] == "eye_to_hand"
    camera = seq.camera.T_cam_target_meas
    if eye_to_hand:  # the marker rides on the hand: the camera is the "target" of the loop
        camera = np.where(np.isfinite(camera), inverse(np.nan_to_num(camera)), np.nan)
    row: dict[str, Any] = {"sequence_id": seq.id, "track": m["track"], "level": m["level"]}
    t0 = time.perf_counter()
    try:
        _, H, C, pairing = pair_streams(
            PoseStream(seq.robot.t, seq.robot.T_base_ee_meas), PoseStream(seq.camera.t, camera)
        )
        row["offset_error_ms"] = 1e3 * abs(pairing.time_offset - seq.time_offset)
        result = calibrate(
            H, C, DEFAULT_HANDEYE_METHOD, gate=Gate(), unknown_scale=float(m["scale"]) != 1.0
        )
    except Cpc2UrdfError as e:
        row.update(ok=False, error=str(e).splitlines()[0][:300])
        return row
    row["runtime_ms"] = 1e3 * (time.perf_counter() - t0)
    row["X_rot_err_deg"], row["X_trans_err_mm"] = _errors(result.X, seq.X)
    row["Y_rot_err_deg"], row["Y_trans_err_mm"] = _errors(result.Z, seq.Y)
    disagree = any(w.startswith("ml is ") for w in result.warnings)
    row.update(ok=True, error="", n_poses=len(H), warnings=len(result.warnings), disagree=disagree)
    return row


def _baseline_rows(results: Path) -> Any:
    """KinHEC's baseline results, the rows comparable with ours (see the module docstring)."""
    import pandas as pd

    b = pd.read_csv(results)
    comparable = (b["track"] == "temporal") == (b["eval_sync"] == "estimated")
    return b[comparable]


def table(ours: Any, baselines: Any) -> str:
    """The per-track markdown table (module docstring)."""
    lines = [
        "| track | n | ours rot [deg] | best baseline | ratio | ours trans [mm] | best baseline "
        "| ratio | refused | refused, a baseline within 2x |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for track, g in ours.groupby("track"):
        b = baselines[baselines["track"] == track]
        ok_b = b[b["ok"]]
        med = ok_b.groupby("solver")[["X_rot_err_deg", "X_trans_err_mm"]].median()
        best_r, best_t = med["X_rot_err_deg"].idxmin(), med["X_trans_err_mm"].idxmin()
        r_b, t_b = med.loc[best_r, "X_rot_err_deg"], med.loc[best_t, "X_trans_err_mm"]
        ok = g[g["ok"]]
        r, t = ok["X_rot_err_deg"].median(), ok["X_trans_err_mm"].median()
        refused = g[~g["ok"]]["sequence_id"]
        solved = ok_b.merge(med, left_on="solver", right_index=True, suffixes=("", "_median"))
        solved = solved[
            (solved["X_rot_err_deg"] <= 2 * solved["X_rot_err_deg_median"])
            & (solved["X_trans_err_mm"] <= 2 * solved["X_trans_err_mm_median"])
        ]
        missed = int(refused.isin(solved["sequence_id"]).sum())
        lines.append(
            f"| {track} | {len(g)} | {r:.3f} | {r_b:.3f} ({best_r}) | {r / r_b:.2f} | {t:.2f} | "
            f"{t_b:.2f} ({best_t}) | {t / t_b:.2f} | {len(refused)} | {missed} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(prog="cpc2urdf study kinhec", description=__doc__.splitlines()[0])
    parser.add_argument("data", help="a KinHEC dataset folder (kinhec generate)")
    parser.add_argument(
        "--baselines", help="kinhec benchmark's results.csv (default DATA/benchmarks/results.csv)"
    )
    parser.add_argument("--tracks", nargs="*", help="only these tracks")
    parser.add_argument("--out", help="write our per-sequence rows as CSV")
    args = parser.parse_args(argv)
    try:
        import pandas as pd
        from kinhec.io import _load_from_row, load_manifest
    except ImportError:
        parser.error("this study needs KinHEC: pip install kinhec")
    root = Path(args.data)
    results = Path(args.baselines) if args.baselines else root / "benchmarks" / "results.csv"
    if not (root / "sequences.parquet").is_file():
        parser.error(f"{root}: not a KinHEC dataset (no sequences.parquet; kinhec generate)")
    if not results.is_file():
        parser.error(f"{results}: no baseline results (kinhec benchmark {root})")
    manifest = load_manifest(root, args.tracks)
    rows = []
    t0 = time.time()
    for k, r in enumerate(manifest.to_dict("records")):
        rows.append(evaluate(_load_from_row(root, r)))
        if k % 25 == 24 or k + 1 == len(manifest):
            print(
                f"\r{k + 1}/{len(manifest)} sequences, {time.time() - t0:.0f} s", end="", flush=True
            )
    print()
    ours = pd.DataFrame(rows)
    if args.out:
        ours.to_csv(args.out, index=False)
    print(table(ours, _baseline_rows(results)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
