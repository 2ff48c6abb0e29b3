"""Study: the stage-1 consistency gate over seeded trials — clean data passed, mistakes named.

A gate must pass clean data in every seeded trial and refuse each mistake a user can
make in a stage-1 file, naming its cause. This study measures both:

- **clean data**: seeded IIS-head experiments (:func:`~cpc2urdf.identification.simulation.stage1_experiment.
  simulate_experiment`, Fig. 10 noise, 0.5 mm / 0.5 deg, M = 9) with the noise stated in the file,
  the same without a noise statement, stereo-measured ones (pixel noise, no statement), and seeded
  random robots (:mod:`~cpc2urdf.identification.simulation.random_robots`, 1-6 joints, M = 2-7,
  Fig. 10 noise stated, and noise-free); each through ``identify`` with its default method; the
  table counts the trials the gate passed;
- **mistakes**: each mistake of :data:`MISTAKES` (a function of a measurement *document*: what a
  user's file looks like after it) applied to seeded experiments; the table counts the trials
  refused with the right cause (the diagnosis' fix, the outlier records, or the degenerate-data
  message).

    cpc2urdf study gate [--trials 200] [--unstated 50] [--stereo 20] [--random 100] [--mistakes 5]
                        [--seed 0] [--out study_gate]

Writes ``gate.md`` and ``gate.json``. Tests apply the same mistakes (``tests/test_consistency.py``).
"""

from __future__ import annotations

import copy
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from cpc2urdf.argparsing import OneLineParser
from cpc2urdf.progress import progress

Doc = dict[str, Any]


def _matrices(doc: Doc, fn: Callable[[np.ndarray], Any]) -> Doc:
    d = copy.deepcopy(doc)
    for rec in d["records"]:
        for f, pose in rec.get("poses", {}).items():
            rec["poses"][f] = fn(np.array(pose["matrix"], dtype=float))
    return d


def metres_as_mm(doc: Doc) -> Doc:
    """Lengths in metres in a file that says mm."""
    d = copy.deepcopy(doc)
    d["units"] = {**d.get("units", {}), "length": "mm"}
    return d


def radians_as_degrees(doc: Doc) -> Doc:
    """Revolute readings in radians in a file that says deg."""
    d = copy.deepcopy(doc)
    d["units"] = {**d.get("units", {}), "angle": "deg"}
    return d


def plates_swapped(doc: Doc, a: str = "plate_left", b: str = "plate_right") -> Doc:
    """The poses of two plates under each other's name."""
    d = copy.deepcopy(doc)
    for rec in d["records"]:
        p = rec["poses"]
        p[a], p[b] = p[b], p[a]
    return d


def joints_swapped(doc: Doc, a: str = "vergence_left", b: str = "vergence_right") -> Doc:
    """Two joints' readings in each other's column."""
    d = copy.deepcopy(doc)
    for rec in d["records"]:
        j = rec["joints"]
        j[a], j[b] = j[b], j[a]
    return d


def poses_inverted(doc: Doc) -> Doc:
    """``T_plate_world`` given instead of ``T_world_plate``."""
    return _matrices(doc, lambda T: {"matrix": np.linalg.inv(T).tolist()})


def rotations_transposed(doc: Doc) -> Doc:
    """Rotation blocks written transposed (translations right)."""

    def tr(T: np.ndarray) -> dict[str, Any]:
        T = T.copy()
        T[:3, :3] = T[:3, :3].T
        return {"matrix": T.tolist()}

    return _matrices(doc, tr)


def quaternion_wxyz(doc: Doc) -> Doc:
    """Quaternions written w, x, y, z in the ``quat_xyzw`` field."""

    def q(T: np.ndarray) -> dict[str, Any]:
        x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
        return {"xyz": T[:3, 3].tolist(), "quat_xyzw": [w, x, y, z]}

    return _matrices(doc, q)


def next_record_poses(doc: Doc) -> Doc:
    """Each record's readings paired with the next record's poses (the last record dropped)."""
    d = copy.deepcopy(doc)
    recs = d["records"]
    for r, nxt in zip(recs, recs[1:], strict=False):
        r["poses"] = copy.deepcopy(nxt["poses"])
    d["records"] = recs[:-1]
    return d


def noise_understated(doc: Doc, factor: float = 20.0) -> Doc:
    """A noise section ``factor`` times smaller than the data's noise."""
    d = copy.deepcopy(doc)
    d["noise"] = {
        **d["noise"],
        "sigma_t_m": d["noise"]["sigma_t_m"] / factor,
        "sigma_r_rad": d["noise"]["sigma_r_rad"] / factor,
    }
    return d


def joint_never_moved(doc: Doc, joint: str = "tilt") -> Doc:
    """The sweep of ``joint`` left out: it reads q0's value in every record."""
    d = copy.deepcopy(doc)
    q0 = d["records"][0]["joints"][joint]
    d["records"] = [r for r in d["records"] if r["joints"][joint] == q0]
    return d


def only_q0(doc: Doc) -> Doc:
    """The q0 record alone."""
    d = copy.deepcopy(doc)
    d["records"] = d["records"][:1]
    return d


def q0_copies(doc: Doc, n: int = 55) -> Doc:
    """``n`` copies of the q0 record."""
    d = copy.deepcopy(doc)
    d["records"] = [copy.deepcopy(d["records"][0]) for _ in range(n)]
    return d


def duplicated_records(doc: Doc) -> Doc:
    """Every record listed twice (a file concatenated with itself)."""
    d = copy.deepcopy(doc)
    d["records"] = d["records"] + copy.deepcopy(d["records"])
    return d


def outliers(doc: Doc, fraction: float = 0.05, seed: int = 1) -> tuple[Doc, list[int]]:
    """One plate of ``fraction`` of the records (not q0) moved 10 mm and turned 5 deg, each about a
    random direction; returns the document and the corrupted record indices."""
    d = copy.deepcopy(doc)
    rng = np.random.default_rng(seed)
    n = len(d["records"])
    bad = sorted(
        int(k) for k in rng.choice(np.arange(1, n), size=max(1, round(fraction * n)), replace=False)
    )
    for k in bad:
        poses = d["records"][k]["poses"]
        f = sorted(poses)[int(rng.integers(len(poses)))]
        T = np.array(poses[f]["matrix"], dtype=float)
        u, w = rng.normal(size=3), rng.normal(size=3)
        T[:3, 3] += 10e-3 * u / np.linalg.norm(u)
        T[:3, :3] = (
            Rotation.from_rotvec(np.radians(5.0) * w / np.linalg.norm(w)).as_matrix() @ T[:3, :3]
        )
        poses[f] = {"matrix": T.tolist()}
    return d, bad


MISTAKES: dict[str, Callable[[Doc], Doc]] = {
    "metres_as_mm": metres_as_mm,
    "radians_as_degrees": radians_as_degrees,
    "plates_swapped": plates_swapped,
    "vergence_swapped": joints_swapped,
    "poses_inverted": poses_inverted,
    "rotations_transposed": rotations_transposed,
    "quaternion_wxyz": quaternion_wxyz,
    "next_record_poses": next_record_poses,
    "noise_understated": noise_understated,
}
# The fix (diagnosis key) that names each mistake.
EXPECTED_FIX = {
    "metres_as_mm": "lengths x1000",
    "radians_as_degrees": "revolute readings x57.3",
    "plates_swapped": "swap plate_left/plate_right",
    "vergence_swapped": "swap vergence_left/vergence_right",
    "poses_inverted": "inverted poses",
    "rotations_transposed": "transposed rotations",
    "quaternion_wxyz": "quaternions w,x,y,z",
    "next_record_poses": "pairing +1",
    "noise_understated": "",
}
DEGENERATE: dict[str, tuple[Callable[[Doc], Doc], str]] = {
    "joint_never_moved": (joint_never_moved, "joint 'tilt' has fewer than two distinct readings"),
    "only_q0": (only_q0, "no joint moves"),
    "q0_copies": (q0_copies, "no joint moves"),
    "duplicated_records": (duplicated_records, "to the last digit"),
}


def _verdict(ms: Any) -> tuple[bool, str]:
    """``(passed, what the gate said)`` for one measurement set through ``identify``."""
    from cpc2urdf.errors import Cpc2UrdfError
    from cpc2urdf.identification.kinematics.methods import identify

    try:
        model = identify(ms)
    except Cpc2UrdfError as e:
        return False, str(e)
    details = model.metadata.provenance.details if model.metadata.provenance else {}
    return bool(details.get("consistency", {}).get("consistent")), ""


def clean_trials(kind: str, seeds: range) -> dict[str, Any]:
    """Run ``identify`` on clean simulated data of one kind; count the gate's passes."""
    from cpc2urdf.errors import Cpc2UrdfError
    from cpc2urdf.files.robot_ref import load_robot
    from cpc2urdf.identification.simulation.random_robots import random_model
    from cpc2urdf.identification.simulation.stage1_experiment import simulate_experiment

    head = load_robot("iis_head")
    passed, skipped, failures, seconds = 0, 0, [], []
    for seed in progress(seeds, kind):
        if kind.startswith("random"):
            rng = np.random.default_rng([seed, 11])
            nominal = random_model(
                rng, int(rng.integers(1, 7)), serial=bool(rng.random() < 0.5), cameras=1
            )
            noise = "none" if kind.endswith("noise-free") else "fig10"
            try:
                _, ms, _ = simulate_experiment(
                    nominal,
                    seed=seed,
                    n_heldout=0,
                    noise=noise,
                    require_view=False,
                    M=int(rng.integers(2, 8)),
                )
            except Cpc2UrdfError:
                skipped += 1
                continue
        else:
            _, ms, _ = simulate_experiment(
                "iis_head",
                seed=seed,
                n_heldout=0,
                noise="stereo" if kind.endswith("stereo") else "fig10",
            )
            ms.spec = head
            if "unstated" in kind:
                ms.metadata.pop("noise", None)
        t0 = time.perf_counter()
        ok, said = _verdict(ms)
        seconds.append(time.perf_counter() - t0)
        passed += ok
        if not ok:
            failures.append({"seed": seed, "said": said})
    n = len(seeds) - skipped
    return {
        "kind": kind,
        "trials": n,
        "passed": passed,
        "skipped": skipped,
        "failures": failures,
        "median_time_s": float(np.median(seconds)) if seconds else None,
    }


def _diagnosis(e: Exception) -> Any:
    from cpc2urdf.errors import InconsistentDataError

    return getattr(e.report, "diagnosis", None) if isinstance(e, InconsistentDataError) else None


def _names_fix(fix: str) -> Callable[[Exception], bool]:
    """A refusal whose diagnosis is the fix ``fix``."""

    def right(e: Exception) -> bool:
        d = _diagnosis(e)
        return d is not None and d.key == fix

    return right


def _names_records(records: list[int]) -> Callable[[Exception], bool]:
    """A refusal naming exactly ``records`` as outliers."""

    def right(e: Exception) -> bool:
        d = _diagnosis(e)
        return d is not None and d.kind == "outliers" and list(d.records) == records

    return right


def _says(words: str) -> Callable[[Exception], bool]:
    def right(e: Exception) -> bool:
        return words in str(e)

    return right


def mistake_trials(seeds: range) -> dict[str, dict[str, Any]]:
    """Apply each mistake to seeded IIS-head experiments; count refusals with the right cause."""
    from cpc2urdf.errors import Cpc2UrdfError
    from cpc2urdf.files.measurements import measurements_from_json, measurements_to_json
    from cpc2urdf.identification.kinematics.methods import identify
    from cpc2urdf.identification.simulation.stage1_experiment import simulate_experiment

    out: dict[str, dict[str, Any]] = {}

    def tally(name: str, ok: bool, said: str) -> None:
        row = out.setdefault(name, {"trials": 0, "named": 0, "wrong": []})
        row["trials"] += 1
        row["named"] += ok
        if not ok:
            row["wrong"].append(said[:300])

    for seed in progress(seeds, "mistakes"):
        _, ms, _ = simulate_experiment("iis_head", seed=seed, n_heldout=0)
        doc = measurements_to_json(ms, robot="iis_head")
        cases: list[tuple[str, Doc, Callable[[Exception], bool]]] = []
        for name, fn in MISTAKES.items():
            cases.append((name, fn(doc), _names_fix(EXPECTED_FIX[name])))
        bad_doc, bad = outliers(doc, seed=seed + 1)
        cases.append(("outliers_5pct", bad_doc, _names_records(bad)))
        for name, (fn, words) in DEGENERATE.items():
            cases.append((name, fn(doc), _says(words)))
        for name, broken, right in cases:
            try:
                identify(measurements_from_json(broken, f"{name}.json"))
            except Cpc2UrdfError as e:
                tally(name, right(e), str(e))
            else:
                tally(name, False, "accepted")
    return out


def format_table(clean: list[dict[str, Any]], mistakes: dict[str, dict[str, Any]]) -> str:
    lines = [
        "# Stage-1 consistency gate",
        "",
        "## Clean data (passed / trials)",
        "",
        "| data | passed | median time [ms] |",
        "|---|---|---|",
    ]
    for c in clean:
        t = "" if c["median_time_s"] is None else f"{c['median_time_s'] * 1e3:.0f}"
        lines.append(f"| {c['kind']} | {c['passed']}/{c['trials']} | {t} |")
    if mistakes:
        lines += [
            "",
            "## Mistakes (refused with the right cause named / trials)",
            "",
            "| mistake | named |",
            "|---|---|",
        ]
        lines += [f"| {k} | {v['named']}/{v['trials']} |" for k, v in mistakes.items()]
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    """``cpc2urdf study gate [options]``."""
    from cpc2urdf.errors import Cpc2UrdfError
    from cpc2urdf.files.jsonio import make_folder, write_atomic, write_json

    p = OneLineParser(prog="cpc2urdf study gate", description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--trials",
        type=int,
        default=200,
        help="IIS-head trials with the noise stated (default 200)",
    )
    p.add_argument(
        "--unstated",
        type=int,
        default=50,
        help="IIS-head trials without a noise statement (default 50)",
    )
    p.add_argument(
        "--stereo", type=int, default=20, help="stereo-measured IIS-head trials (default 20)"
    )
    p.add_argument(
        "--random",
        type=int,
        default=100,
        help="random-robot trials, noisy and noise-free each (default 100)",
    )
    p.add_argument("--mistakes", type=int, default=5, help="trials per mistake (default 5)")
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument("--out", default="study_gate", help="output folder (default study_gate)")
    args = p.parse_args(argv)
    if min(args.trials, args.unstated, args.stereo, args.random, args.mistakes) < 0:
        raise Cpc2UrdfError("trial counts must be >= 0")
    out = make_folder(args.out)
    s = args.seed
    clean = [
        clean_trials(kind, range(s, s + n))
        for kind, n in (
            ("IIS-head, Fig. 10 noise stated", args.trials),
            ("IIS-head, Fig. 10 noise unstated", args.unstated),
            ("IIS-head, stereo", args.stereo),
            ("random robots, Fig. 10 noise stated", args.random),
            ("random robots, noise-free", args.random),
        )
        if n
    ]
    mistakes = mistake_trials(range(s, s + args.mistakes)) if args.mistakes else {}
    table = format_table(clean, mistakes)
    write_atomic(out / "gate.md", table)
    write_json(out / "gate.json", {"setting": vars(args), "clean": clean, "mistakes": mistakes})
    print(table)
    print(f"wrote {out / 'gate.md'}, {out / 'gate.json'}")
    return 0


__all__ = [
    "DEGENERATE",
    "EXPECTED_FIX",
    "MISTAKES",
    "clean_trials",
    "main",
    "mistake_trials",
    "outliers",
]
