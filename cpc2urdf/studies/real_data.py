"""``cpc2urdf study real-data``: calibration on measurements recorded on three real robots, held out.

The data (``cpc2urdf/studies/data/real/``, from FIGAROH's examples, README there) are TIAGo's hand
markers, a point on TALOS's left gripper and a frame on UR10's wrist, each with the URDF it was
recorded against. For each set, with the data's own 5-fold split (a seeded permutation,
``numpy.array_split``): the held-out RMS distance of the measured points of every level of
:mod:`~cpc2urdf.identification.kinematics.prior_fit` fitted alone, and of ``identify --method map``
(the level chosen, the gate and the whole-range check run on the training records only); the error the chosen fits predicted for left-out
records; and, fitted on every record, how far the calibrated model's prediction of the measured
point moves from the URDF's over the robot's whole joint range (500 seeded readings within the
URDF's limits), the seconds it took, and which level it chose.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cpc2urdf.argparsing import OneLineParser
from cpc2urdf.files.figaroh_csv import load_figaroh_csv
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.identification.kinematics.map_identify import calibrate
from cpc2urdf.identification.kinematics.prior_fit import (
    LEVELS,
    MapFit,
    cross_validate,
    first_point,
    fit_map,
    readings_within_limits,
)
from cpc2urdf.urdf.pinocchio import gravity_loads
from cpc2urdf.urdf.robot import UrdfRobot, load_urdf_robot

DATA = Path(__file__).parent / "data" / "real"
RANGE_SAMPLES = 500  # [-]: readings over the whole joint range for the divergence


@dataclass(frozen=True)
class RealSet:
    """One data set and the reference figures the data's README gives (mm).

    Attributes:
        name: Row label.
        urdf: URDF, relative to :data:`DATA`.
        csv: FIGAROH CSV, relative to :data:`DATA`.
        link: The link the measured points ride on.
        markers: The markers used (None: every distinct one).
        nominal_mm: Held-out RMS of the URDF unchanged, measuring frame fitted.
        figaroh_mm: Held-out RMS of FIGAROH 1.0.2.
        figaroh_p95_mm: FIGAROH's full-range divergence from the URDF (p95), where given.
    """

    name: str
    urdf: str
    csv: str
    link: str
    markers: tuple[str, ...] | None
    nominal_mm: float
    figaroh_mm: float
    figaroh_p95_mm: float | None


SETS = (
    RealSet(
        "TIAGo, marker 1",
        "tiago/tiago_48_schunk.urdf",
        "tiago/qualysis_base_hand_calibration.csv",
        "wrist_ft_tool_link",
        ("m1",),
        4.54,
        6.03,
        23.0,
    ),
    RealSet(
        "TIAGo, markers 1-3",
        "tiago/tiago_48_schunk.urdf",
        "tiago/qualysis_base_hand_calibration.csv",
        "wrist_ft_tool_link",
        None,
        4.63,
        4.30,
        None,
    ),
    RealSet(
        "TALOS",
        "talos/talos_full_v2.urdf",
        "talos/talos_left_arm_02_10_contact.csv",
        "gripper_left_base_link",
        None,
        5.45,
        0.85,
        40.0,
    ),
    RealSet(
        "UR10", "ur10/ur10_robot.urdf", "ur10/calibration.csv", "tool0", None, 4.13, 4.12, 19.0
    ),
)


def load_set(rs: RealSet) -> tuple[UrdfRobot, MeasurementSet]:
    """The robot and its measurements (only ``rs.markers`` when given)."""
    robot = load_urdf_robot(DATA / rs.urdf)
    ms = load_figaroh_csv(DATA / rs.csv, robot, rs.link)
    if rs.markers is not None:
        ms.markers = {m: ms.markers[m] for m in rs.markers}
        ms.marker_points = {m: ms.marker_points[m] for m in rs.markers}
    return robot, ms


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e**2)))


def divergence(fit: MapFit, urdf_fit: MapFit, ms: MeasurementSet, seed: int = 0) -> np.ndarray:
    """Distance [m] between the calibrated (deflected by gravity where it has compliances) and the
    URDF's prediction of the first measured point, at :data:`RANGE_SAMPLES` seeded readings within
    the joints' limits."""
    Q = readings_within_limits(ms.structure, RANGE_SAMPLES, seed)
    Qd = fit.deflected(Q, gravity_loads(ms, Q) if fit.compliance else None)
    return np.linalg.norm(first_point(fit, ms, Qd) - first_point(urdf_fit, ms, Q), axis=1)


def run_set(rs: RealSet) -> dict[str, Any]:
    """Every figure of one row (module docstring)."""
    robot, ms = load_set(rs)
    nominal = ms.spec.nominal_model() if ms.spec is not None else None
    assert nominal is not None
    loads = gravity_loads(ms)
    levels = [lv for lv in LEVELS if lv != "compliance" or loads is not None]
    row: dict[str, Any] = {
        "set": rs.name,
        "records": ms.n_records,
        "nominal_mm": rs.nominal_mm,
        "figaroh_mm": rs.figaroh_mm,
        "figaroh_p95_mm": rs.figaroh_p95_mm,
    }
    for lv in levels:

        def one_level(m: MeasurementSet, L: np.ndarray | None, lv: str = lv) -> MapFit:
            return fit_map(nominal, m, lv, loads=L)

        row[f"{lv}_mm"] = _rms(cross_validate(ms, one_level, loads)) * 1e3
    chosen: list[str] = []
    predicted: list[float] = []

    def default(m: MeasurementSet, L: np.ndarray | None) -> MapFit:
        fit = calibrate(m, nominal, loads=L).fit
        chosen.append(fit.level)
        predicted.append(fit.loo_rms_m)
        return fit

    e = cross_validate(ms, default, loads)
    row["map_mm"] = _rms(e) * 1e3
    row["predicted_mm"] = float(np.sqrt(np.mean(np.square(predicted)))) * 1e3
    row["chosen_per_fold"] = chosen
    t0 = time.perf_counter()
    cal = calibrate(ms, nominal, loads=loads)
    row["seconds"] = time.perf_counter() - t0
    row["chosen"] = cal.fit.level
    d = divergence(cal.fit, cal.selection.fits["frames"], ms)
    row["divergence_mm"] = {
        "median": float(np.median(d)) * 1e3,
        "p95": float(np.percentile(d, 95)) * 1e3,
        "max": float(d.max()) * 1e3,
    }
    row["data_share"] = cal.fit.data_share
    return row


SCALE_RECORDS = 6001  # [-]: simulated records of the scale check


def scale_seconds(level: str = "geometry", seed: int = 0) -> tuple[float, float]:
    """Seconds of one ``level`` fit (no choice among levels) on :data:`SCALE_RECORDS` simulated
    TALOS records (readings within the data's box, the real data's fit as the truth, 0.3 mm
    noise), and the RMS error of the fitted points [m]."""
    _, ms = load_set(SETS[2])
    nominal = ms.spec.nominal_model() if ms.spec is not None else None
    assert nominal is not None
    rng = np.random.default_rng(seed)
    q = rng.uniform(ms.q.min(0), ms.q.max(0), (SCALE_RECORDS, ms.structure.n_joints))
    truth = fit_map(nominal, ms, "geometry")
    m = next(iter(truth.markers))
    frame = ms.markers[m].frame
    T = truth.model.fk(q, [frame])[frame]
    y = T[:, :3, :3] @ truth.markers[m] + T[:, :3, 3] + rng.normal(0, 3e-4, (SCALE_RECORDS, 3))
    big = MeasurementSet.from_arrays(
        ms.structure, q, {}, markers={m: ms.markers[m]}, marker_points={m: y}
    )
    t0 = time.perf_counter()
    fit = fit_map(nominal, big, level)
    return time.perf_counter() - t0, fit.rms_m


def format_table(rows: list[dict[str, Any]]) -> str:
    """The Markdown table of :func:`run_set` rows."""
    head = (
        "| set | URDF (frames fitted) | FIGAROH 1.0.2 | offsets | geometry | compliance | **map (default)** "
        "| predicted | chosen (all records) | full-range p95 (FIGAROH) | seconds |"
    )
    lines = [head, "|" + "---|" * 11]
    for r in rows:
        p95 = f"{r['divergence_mm']['p95']:.1f}" + (
            f" ({r['figaroh_p95_mm']:.0f})" if r["figaroh_p95_mm"] else ""
        )
        comp = f"{r['compliance_mm']:.2f}" if "compliance_mm" in r else "—"
        ok = r["map_mm"] <= min(r["nominal_mm"], r["figaroh_mm"]) + 5e-3
        lines.append(
            f"| {r['set']} | {r['frames_mm']:.2f} ({r['nominal_mm']:.2f}) | {r['figaroh_mm']:.2f} | "
            f"{r['offsets_mm']:.2f} | {r['geometry_mm']:.2f} | {comp} | **{r['map_mm']:.2f}**{'' if ok else ' ✗'} | "
            f"{r['predicted_mm']:.2f} | {r['chosen']} | {p95} | {r['seconds']:.1f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = OneLineParser(prog="cpc2urdf study real-data", description=__doc__.splitlines()[0])
    p.add_argument("--json", help="also write every figure to this JSON file")
    p.add_argument("--set", action="append", choices=[s.name for s in SETS], help="only these sets")
    args: argparse.Namespace = p.parse_args(argv)
    rows = []
    for rs in SETS:
        if args.set and rs.name not in args.set:
            continue
        rows.append(run_set(rs))
        print(f"  {rs.name}: done", flush=True)
    print(format_table(rows))
    print(
        "mm, held-out RMS of the measured points over the data's 5-fold split; URDF: ours (the data "
        "README's in brackets); predicted: leave-one-record-out RMS of the chosen fits; p95: distance "
        "from the URDF's prediction over the whole joint range, fitted on every record"
    )
    seconds, rms = scale_seconds()
    print(
        f"scale: {SCALE_RECORDS:,} simulated TALOS records, geometry level fixed (no choice): {seconds:.2f} s "
        f"(fit rms {rms * 1e3:.3f} mm)"
    )
    if args.json:
        Path(args.json).write_text(json.dumps({"sets": rows, "scale_seconds": seconds}, indent=1))
    return 0


__all__ = [
    "SETS",
    "RealSet",
    "divergence",
    "format_table",
    "load_set",
    "main",
    "run_set",
    "scale_seconds",
]
