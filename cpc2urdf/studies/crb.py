"""Study: how close do the closed form and the refinement come to the Cramér-Rao bound?

Seeded Monte Carlo trials at the paper's setting (IIS-head, one joint at a time, M = 9, Fig. 10
noise σ_t = 0.5 mm per translation entry and a random-axis rotation of angle N(0, 0.5°)). Each
trial draws a true robot (:func:`cpc2urdf.identification.simulation.stage1_experiment.simulate_experiment`),
identifies it in closed form (sec. 4.2) and refines that with :func:`refine.refine`, and compares
both with the bound:

- **Parameters.** The bound is ``C = (J^T J)^-1`` with ``J`` the weighted Jacobian at the *true*
  robot in its own minimal chart (32 parameters, :mod:`parametrization`). An estimate's error
  ``e`` is the true chart's coordinates of the estimate (gauge-aligned, so only what the data can
  see is compared). An efficient estimator has ``E[e^T C^-1 e] = 32``; we report
  ``sqrt(mean(e^T C^-1 e) / 32)`` (1 = at the bound), and the RMS error of the angle parameters
  [mrad] and length parameters [mm] next to the bound's RMS.
- **Held-out positioning.** For each held-out configuration and plate, the bound predicts the
  mean squared origin error ``trace(G C G^T)`` (:mod:`uncertainty`); the observed one is
  ``|p_est - p_true|^2``. We report both RMS values [mm] and their ratio.

"Bound" means the covariance of the Gaussian noise with the same second moments as Fig. 10's
(the rotation vector ``u·φ`` has per-axis variance σ_r²/3); it is what weighted least squares can
reach and what the refinement's weights assume. (Fig. 10's rotation noise is not Gaussian, and
its exact Fisher information is unbounded at zero angle, so a formal CRB of that model is not a
useful reference.) A third row refines with rotation residuals divided by σ_r per axis instead
of σ_r/√3, to show what that weighting costs.

A fourth row is the pipeline ``cpc2urdf identify`` runs by default (closed form, refinement and
the consistency gate, :mod:`~cpc2urdf.identification.kinematics.gate.pose_gate`): its estimate is the
refinement's, and the table counts the trials whose clean data the gate passed.

Robust mode (``--outliers 0.05``, default): the same trials with one plate of 5 % of the records
corrupted by 10 mm / 5° (a mis-detected plate); robust refinement (started from the closed form
of the corrupted data) against the clean refinement, and whether exactly the corrupted poses are
named; and whether the default pipeline refuses the corrupted data naming exactly the corrupted
records.

    cpc2urdf study crb [--trials 50] [--M 9] [--sigma-mm 0.5] [--sigma-deg 0.5] [--seed 0]
                       [--heldout 100] [--outliers 0.05] [--out study_crb]

Writes ``crb.md`` (table), ``crb.json`` and ``crb.png`` (normalised parameter errors against the
chi-square law of an efficient estimator; observed vs predicted held-out error per trial).
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cpc2urdf.argparsing import OneLineParser
from cpc2urdf.progress import progress

if TYPE_CHECKING:  # the library is imported inside the functions (fast `cpc2urdf --help`)
    from cpc2urdf.files.measurements import MeasurementSet
    from cpc2urdf.identification.kinematics.refine import RefinementResult
    from cpc2urdf.model import CPCModel

ESTIMATORS = (
    "closed-form",
    "refined",
    "refined (rotation / sigma_r per axis)",
    "default: refined + consistency gate",
)
DEFAULT = ESTIMATORS[3]
AT_BOUND = 1.10  # the "within ~10 %"


def run_trial(
    seed: int,
    M: int,
    sigma_t: float,
    sigma_r: float,
    n_heldout: int,
    robot: str = "iis_head",
    outliers: float = 0.0,
) -> dict[str, Any]:
    """One trial: errors of every estimator and the bound's predictions."""
    from cpc2urdf.identification.kinematics.closed_form import identify_closed_form
    from cpc2urdf.identification.kinematics.methods import identify
    from cpc2urdf.identification.kinematics.parametrization import Parametrization
    from cpc2urdf.identification.kinematics.refine import refine
    from cpc2urdf.identification.kinematics.uncertainty import cramer_rao_covariance
    from cpc2urdf.identification.simulation.stage1_experiment import simulate_experiment

    truth, measured, heldout = simulate_experiment(
        robot, seed=seed, M=M, noise="fig10", sigma_t=sigma_t, sigma_r=sigma_r, n_heldout=n_heldout
    )
    frames = measured.frames
    chart, C = cramer_rao_covariance(truth, measured.q, frames, sigma_t, sigma_r)
    F = np.linalg.inv(C)
    P = chart.n_params
    angle = np.array([u == "rad" for u in chart.units])
    # Held-out prediction of the bound: trace(G C G^T) per configuration and plate.
    _, D = Parametrization(truth, frames).pose_jacobian(np.zeros(P), heldout.q)
    pred_ms = float(
        np.mean([np.einsum("nip,pq,niq->n", D[f][:, :3], C, D[f][:, :3]) for f in frames])
    )

    t0 = time.perf_counter()
    cf, _ = identify_closed_form(measured)
    t_cf = time.perf_counter() - t0
    t0 = time.perf_counter()
    ref = refine(cf, measured, sigma_t, sigma_r, warn=False)
    t_ref = time.perf_counter() - t0
    ref_axis = refine(
        cf, measured, sigma_t, sigma_r * math.sqrt(3.0), warn=False
    )  # 1/sigma_r per axis
    # The pipeline `cpc2urdf identify` runs by default (with its consistency gate), kept whatever
    # the gate says so that a false alarm would show here as a count, not as a missing trial.
    default = identify(measured, accept_inconsistent=True)
    gate = default.metadata.provenance.details["consistency"] if default.metadata.provenance else {}
    out: dict[str, Any] = {
        "seed": seed,
        "n_params": P,
        "bound_rms_angle_mrad": float(np.sqrt(np.mean(np.diag(C)[angle])) * 1e3),
        "bound_rms_length_mm": float(np.sqrt(np.mean(np.diag(C)[~angle])) * 1e3),
        "bound_heldout_rms_mm": math.sqrt(pred_ms) * 1e3,
        "time_closed_form_s": t_cf,
        "time_refined_s": t_ref,
        "refined_variance_factor": ref.covariance.variance_factor,
        "gate_passed": bool(gate.get("consistent")),
        "refined_predicted_heldout_rms_mm": float(
            np.sqrt(np.mean([_own_prediction(ref, heldout.q, f) for f in frames])) * 1e3
        ),
    }
    T_true = truth.fk(heldout.q, frames)
    for name, model in zip(ESTIMATORS, (cf, ref.model, ref_axis.model, default), strict=True):
        e = chart.vector_from_model(model)
        T = model.fk(heldout.q, frames)
        sq = np.concatenate(
            [np.sum((T[f][:, :3, 3] - T_true[f][:, :3, 3]) ** 2, axis=1) for f in frames]
        )
        out[name] = {
            "normalised": float(e @ F @ e / P),
            "sq_angle": float(np.mean(e[angle] ** 2)),
            "sq_length": float(np.mean(e[~angle] ** 2)),
            "ratio_per_param": (e**2 / np.diag(C)).tolist(),
            "heldout_ms": float(np.mean(sq)),
            "heldout_mean_mm": float(np.mean(np.sqrt(sq)) * 1e3),
        }
    out["names"] = list(chart.names)
    if outliers > 0:
        out["outliers"] = _outlier_trial(
            measured, cf, ref.model, heldout, T_true, frames, sigma_t, sigma_r, outliers, seed
        )
    return out


def corrupt(
    measured: MeasurementSet,
    fraction: float,
    rng: np.random.Generator,
    shift: float = 10e-3,
    angle: float = math.radians(5.0),
) -> tuple[MeasurementSet, list[tuple[int, str]]]:
    """Mis-detected plates: ``shift`` [m] in a random direction and ``angle`` [rad] about a random
    axis on one random plate of ``round(fraction * N)`` random records (at least one)."""
    from scipy.spatial.transform import Rotation

    from cpc2urdf.files.measurements import MeasurementSet

    n = measured.n_records
    frames = measured.frames
    bad = np.sort(rng.choice(n, size=max(1, round(fraction * n)), replace=False))
    poses = {f: P.copy() for f, P in measured.poses.items()}
    hit = []
    for k in bad:
        f = frames[int(rng.integers(len(frames)))]
        u, w = rng.normal(size=3), rng.normal(size=3)
        poses[f][k, :3, 3] += shift * u / np.linalg.norm(u)
        poses[f][k, :3, :3] = (
            Rotation.from_rotvec(angle * w / np.linalg.norm(w)).as_matrix() @ poses[f][k, :3, :3]
        )
        hit.append((int(k), f))
    dirty = MeasurementSet(
        measured.structure,
        measured.q,
        poses,
        measured.source,
        measured.robot,
        list(measured.labels),
        metadata=dict(measured.metadata),
    )
    dirty.spec = measured.spec
    return dirty, hit


def _outlier_trial(
    measured: MeasurementSet,
    cf: CPCModel,
    clean: CPCModel,
    heldout: MeasurementSet,
    T_true: dict[str, np.ndarray],
    frames: list[str],
    sigma_t: float,
    sigma_r: float,
    fraction: float,
    seed: int,
) -> dict[str, Any]:
    """Corrupt ``fraction`` of the records; robust refinement vs the clean refinement."""
    from cpc2urdf.errors import DegenerateDataError, InconsistentDataError
    from cpc2urdf.identification.kinematics.closed_form import identify_closed_form
    from cpc2urdf.identification.kinematics.methods import identify
    from cpc2urdf.identification.kinematics.refine import refine

    dirty, hit = corrupt(measured, fraction, np.random.default_rng([seed, 7]))

    def held_rms(model: CPCModel) -> float:
        T = model.fk(heldout.q, frames)
        return float(
            np.sqrt(
                np.mean(
                    np.concatenate(
                        [
                            np.sum((T[f][:, :3, 3] - T_true[f][:, :3, 3]) ** 2, axis=1)
                            for f in frames
                        ]
                    )
                )
            )
        )

    try:
        start, start_name = identify_closed_form(dirty)[0], "closed form of the corrupted data"
    except Exception:  # noqa: BLE001 - a corrupted q0 can defeat the closed form; start elsewhere
        start, start_name = cf, "clean closed form"
    t0 = time.perf_counter()
    robust = refine(start, dirty, sigma_t, sigma_r, robust=True, warn=False)
    t_robust = time.perf_counter() - t0
    plain = refine(start, dirty, sigma_t, sigma_r, warn=False)
    found = sorted((o.record, o.frame) for o in robust.outliers)
    # The default pipeline (refined + consistency gate) on the corrupted data: it must refuse and
    # name exactly the corrupted records. Any refusal counts as one (corrupted records can also
    # make the data degenerate, e.g. a joint that no longer moves); only the gate's names records.
    refusal = ""
    try:
        identify(dirty)
        named: list[int] = []
        refused = False
    except DegenerateDataError as e:
        refused, refusal = True, type(e).__name__
        d = getattr(e.report, "diagnosis", None) if isinstance(e, InconsistentDataError) else None
        named = sorted(d.records) if d is not None else []
    return {
        "corrupted": sorted(hit),
        "flagged": found,
        "exact": found == sorted(hit),
        "missed": len(set(hit) - set(found)),
        "false_alarms": len(set(found) - set(hit)),
        "clean_rms_mm": held_rms(clean) * 1e3,
        "robust_rms_mm": held_rms(robust.model) * 1e3,
        "plain_rms_mm": held_rms(plain.model) * 1e3,
        "closed_form_dirty_rms_mm": held_rms(start) * 1e3,
        "start": start_name,
        "time_robust_s": t_robust,
        "default_refused": refused,
        "default_refusal": refusal,
        "default_named_exactly": refused and named == sorted({k for k, _ in hit}),
    }


def _own_prediction(res: RefinementResult, q: np.ndarray, frame: str) -> float:
    """Mean predicted squared error from the refinement's own (estimated) covariance."""
    from cpc2urdf.identification.kinematics.uncertainty import predicted_position_std

    return float(np.mean(predicted_position_std(res.model, q, [frame])[frame] ** 2))


def summarise(trials: list[dict[str, Any]]) -> dict[str, Any]:
    """Aggregate the trials: ratios to the bound per estimator."""
    P = trials[0]["n_params"]
    names = trials[0]["names"]
    b_ang = math.sqrt(np.mean([t["bound_rms_angle_mrad"] ** 2 for t in trials]))
    b_len = math.sqrt(np.mean([t["bound_rms_length_mm"] ** 2 for t in trials]))
    b_held = math.sqrt(np.mean([t["bound_heldout_rms_mm"] ** 2 for t in trials]))
    rows = {}
    for est in ESTIMATORS:
        per_param = np.sqrt(np.mean([t[est]["ratio_per_param"] for t in trials], axis=0))
        worst = int(np.argmax(per_param))
        held = math.sqrt(np.mean([t[est]["heldout_ms"] for t in trials])) * 1e3
        rows[est] = {
            "param_ratio": math.sqrt(np.mean([t[est]["normalised"] for t in trials])),
            "rms_angle_mrad": math.sqrt(np.mean([t[est]["sq_angle"] for t in trials])) * 1e3,
            "rms_length_mm": math.sqrt(np.mean([t[est]["sq_length"] for t in trials])) * 1e3,
            "worst_param": names[worst],
            "worst_param_ratio": float(per_param[worst]),
            "heldout_rms_mm": held,
            "heldout_ratio": held / b_held,
            "heldout_mean_mm": float(np.mean([t[est]["heldout_mean_mm"] for t in trials])),
        }
    # Monte Carlo uncertainty of the parameter ratio for an efficient estimator (chi-square(P)/P).
    n = len(trials)
    mc = math.sqrt(1.0 + 2.0 * math.sqrt(2.0 / (P * n))) - 1.0
    ref_vs_cf = [t["refined"]["heldout_ms"] <= t["closed-form"]["heldout_ms"] for t in trials]
    extra: dict[str, Any] = {}
    if "outliers" in trials[0]:
        o = [t["outliers"] for t in trials]
        ratio = np.array([x["robust_rms_mm"] / x["clean_rms_mm"] for x in o])
        extra["outliers"] = {
            "exact_detection": f"{sum(x['exact'] for x in o)}/{n}",
            "corrupted_poses": int(sum(len(x["corrupted"]) for x in o)),
            "missed": int(sum(x["missed"] for x in o)),
            "false_alarms": int(sum(x["false_alarms"] for x in o)),
            "robust_over_clean_mean": float(ratio.mean()),
            "robust_over_clean_max": float(ratio.max()),
            "within_1.2": f"{int(np.sum(ratio <= 1.2))}/{n}",
            "plain_over_clean_mean": float(
                np.mean([x["plain_rms_mm"] / x["clean_rms_mm"] for x in o])
            ),
            "closed_form_dirty_over_clean_mean": float(
                np.mean([x["closed_form_dirty_rms_mm"] / x["clean_rms_mm"] for x in o])
            ),
            "time_robust_ms": 1e3 * float(np.median([x["time_robust_s"] for x in o])),
            "default_refused": f"{sum(x['default_refused'] for x in o)}/{n}",
            "default_named_exactly": f"{sum(x['default_named_exactly'] for x in o)}/{n}",
        }
    return {
        **extra,
        "trials": n,
        "n_params": P,
        "bound_rms_angle_mrad": b_ang,
        "bound_rms_length_mm": b_len,
        "bound_heldout_rms_mm": b_held,
        "estimators": rows,
        "refined_not_worse_than_closed_form": f"{sum(ref_vs_cf)}/{n}",
        "monte_carlo_2sigma_of_ratio": mc,
        "time_closed_form_ms": 1e3 * float(np.median([t["time_closed_form_s"] for t in trials])),
        "time_refined_ms": 1e3 * float(np.median([t["time_refined_s"] for t in trials])),
        "refined_variance_factor_mean": float(
            np.mean([t["refined_variance_factor"] for t in trials])
        ),
        "gate_passed_clean": f"{sum(t['gate_passed'] for t in trials)}/{n}",
        "refined_own_prediction_rms_mm": math.sqrt(
            np.mean([t["refined_predicted_heldout_rms_mm"] ** 2 for t in trials])
        ),
    }


def format_table(s: dict[str, Any], setting: str) -> str:
    """Markdown table with a verdict."""
    lines = [
        f"# Cramér-Rao comparison ({setting}, {s['trials']} trials, {s['n_params']} parameters)",
        "",
        f"Bound (per trial at the true robot, RMS over trials): angles {s['bound_rms_angle_mrad']:.3f} mrad, "
        f"lengths {s['bound_rms_length_mm']:.3f} mm, held-out positioning {s['bound_heldout_rms_mm']:.3f} mm RMS.",
        "",
        "| estimator | param. error / bound | angles RMS [mrad] | lengths RMS [mm] | worst parameter (ratio) "
        "| held-out RMS [mm] | held-out / bound | held-out mean [mm] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for est, r in s["estimators"].items():
        lines.append(
            f"| {est} | {r['param_ratio']:.3f} | {r['rms_angle_mrad']:.3f} | {r['rms_length_mm']:.3f} | "
            f"{r['worst_param']} ({r['worst_param_ratio']:.2f}) | {r['heldout_rms_mm']:.3f} | "
            f"{r['heldout_ratio']:.3f} | {r['heldout_mean_mm']:.3f} |"
        )
    ref = s["estimators"]["refined"]
    at = ref["param_ratio"] <= AT_BOUND and ref["heldout_ratio"] <= AT_BOUND
    lines += [
        "",
        f"Ratios are RMS over trials (parameters: sqrt(mean e^T C^-1 e / P)); 1 = at the bound. "
        f"Monte Carlo spread of the parameter ratio of an efficient estimator with {s['trials']} trials: "
        f"±{s['monte_carlo_2sigma_of_ratio']:.3f} (2σ).",
        f"Refined held-out error <= closed form in {s['refined_not_worse_than_closed_form']} trials. "
        f"Median time: closed form {s['time_closed_form_ms']:.0f} ms, refinement {s['time_refined_ms']:.0f} ms.",
        f"Refinement's own covariance (at its estimate) predicts {s['refined_own_prediction_rms_mm']:.3f} mm "
        f"held-out RMS; mean variance factor {s['refined_variance_factor_mean']:.3f}.",
        "",
        f"Verdict: the refined estimate is {'AT' if at else 'NOT at'} the bound (within {AT_BOUND - 1:.0%}): "
        f"parameters {ref['param_ratio']:.3f}, held-out {ref['heldout_ratio']:.3f}.",
        f"Default pipeline (`cpc2urdf identify`: refined + consistency gate): parameters "
        f"{s['estimators'][DEFAULT]['param_ratio']:.3f} x the bound; the gate passed the clean data in "
        f"{s['gate_passed_clean']} trials.",
    ]
    if "outliers" in s:
        o = s["outliers"]
        lines += [
            "",
            f"## Robust mode ({o['corrupted_poses']} corrupted poses: 10 mm / 5° on one plate of {s['outlier_fraction']:.0%} of the records)",
            "",
            "| exact detection | missed | false alarms | robust / clean held-out RMS (mean, max) | within 1.2x "
            "| plain / clean | closed form (corrupted) / clean | robust time [ms] |",
            "|---|---|---|---|---|---|---|---|",
            f"| {o['exact_detection']} | {o['missed']} | {o['false_alarms']} | {o['robust_over_clean_mean']:.3f}, "
            f"{o['robust_over_clean_max']:.3f} | {o['within_1.2']} | {o['plain_over_clean_mean']:.2f} | "
            f"{o['closed_form_dirty_over_clean_mean']:.2f} | {o['time_robust_ms']:.0f} |",
            "",
            f"Default pipeline (refined + consistency gate) on the corrupted data: refused in {o['default_refused']} "
            f"trials, naming exactly the corrupted records in {o['default_named_exactly']}.",
        ]
    return "\n".join(lines) + "\n"


def plot(trials: list[dict[str, Any]], s: dict[str, Any], path: Path, setting: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.stats import chi2

    P = s["n_params"]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    top = max(
        3.0, float(np.percentile([t["closed-form"]["normalised"] for t in trials], 98)) * 1.05
    )
    x = np.linspace(0.0, top, 400)
    for est, color in zip(ESTIMATORS[:2], ("tab:red", "tab:blue"), strict=True):
        v = np.clip([t[est]["normalised"] for t in trials], 0.0, top)
        ax[0].hist(
            v,
            bins=np.linspace(0, top, 41),
            density=True,
            alpha=0.5,
            color=color,
            label=f"{est} (RMS ratio {s['estimators'][est]['param_ratio']:.2f})",
        )
    ax[0].plot(x, chi2.pdf(x * P, P) * P, "k-", lw=1.5, label="at the bound: χ²(P)/P")
    ax[0].set_xlabel("normalised parameter error e^T C^-1 e / P")
    ax[0].set_ylabel("density")
    ax[0].set_title("parameters vs Cramér-Rao bound")
    ax[0].legend(fontsize=8)
    b = np.array([t["bound_heldout_rms_mm"] for t in trials])
    for est, color, m in zip(ESTIMATORS[:2], ("tab:red", "tab:blue"), ("s", "o"), strict=True):
        o = np.sqrt([t[est]["heldout_ms"] for t in trials]) * 1e3
        ax[1].scatter(b, o, s=18, color=color, marker=m, label=est)
    lim = [
        0.0,
        max(
            0.1,
            float(np.max([np.sqrt(t["closed-form"]["heldout_ms"]) * 1e3 for t in trials])) * 1.05,
        ),
    ]
    ax[1].plot(lim, lim, "k--", lw=1, label="observed = bound")
    ax[1].set_xlim(0, max(lim[1], float(b.max()) * 1.1))
    ax[1].set_ylim(lim)
    ax[1].set_xlabel("bound: predicted held-out RMS error [mm]")
    ax[1].set_ylabel("observed held-out RMS error [mm]")
    ax[1].set_title("held-out positioning, per trial")
    ax[1].legend(fontsize=8)
    fig.suptitle(f"cpc2urdf study crb: {setting}", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str]) -> int:
    """``cpc2urdf study crb [options]``."""
    from cpc2urdf.errors import Cpc2UrdfError
    from cpc2urdf.files.jsonio import make_folder, write_atomic, write_json

    p = OneLineParser(prog="cpc2urdf study crb", description=__doc__.split("\n\n")[0])
    p.add_argument("--trials", type=int, default=50, help="seeded trials (default 50)")
    p.add_argument(
        "--M", type=int, default=9, help="measurements per joint (default 9, the paper's)"
    )
    p.add_argument(
        "--sigma-mm", type=float, default=0.5, help="translation noise per entry [mm] (default 0.5)"
    )
    p.add_argument(
        "--sigma-deg", type=float, default=0.5, help="rotation noise angle [deg] (default 0.5)"
    )
    p.add_argument("--seed", type=int, default=0, help="first trial seed (default 0)")
    p.add_argument(
        "--heldout", type=int, default=100, help="held-out configurations per trial (default 100)"
    )
    p.add_argument(
        "--robot", default="iis_head", help="robot with nominal geometry (default iis_head)"
    )
    p.add_argument(
        "--outliers",
        type=float,
        default=0.05,
        help="also corrupt this fraction of records (10 mm / 5 deg) and test robust mode; 0 to skip (default 0.05)",
    )
    p.add_argument("--out", default="study_crb", help="output folder (default study_crb)")
    args = p.parse_args(argv)
    if (
        args.trials < 2
        or args.M < 2
        or args.heldout < 1
        or not (args.sigma_mm > 0 and args.sigma_deg > 0)
    ):
        raise Cpc2UrdfError("need --trials >= 2, --M >= 2, --heldout >= 1 and positive sigmas")
    if not 0.0 <= args.outliers < 0.5:
        raise Cpc2UrdfError(f"--outliers must be in [0, 0.5), got {args.outliers}")
    sigma_t, sigma_r = args.sigma_mm * 1e-3, math.radians(args.sigma_deg)
    from cpc2urdf.files.robot_ref import load_robot

    load_robot(
        args.robot
    ).nominal_model()  # a robot that is missing or has no nominal geometry: before --out
    trials = []
    for k in progress(range(args.trials), "crb"):
        trials.append(
            run_trial(
                args.seed + k, args.M, sigma_t, sigma_r, args.heldout, args.robot, args.outliers
            )
        )
        if (
            k == 0
        ):  # a robot the study cannot simulate (e.g. no plate to measure) fails before --out exists
            out = make_folder(args.out)
    s = summarise(trials)
    s["outlier_fraction"] = args.outliers
    setting = f"{args.robot}, M = {args.M}, σ = {args.sigma_mm:g} mm / {args.sigma_deg:g}°"
    table = format_table(s, setting)
    write_atomic(out / "crb.md", table)
    write_json(out / "crb.json", {"setting": vars(args), "summary": s, "trials": trials})
    plot(trials, s, out / "crb.png", setting)
    print(table)
    print(f"wrote {out / 'crb.md'}, {out / 'crb.json'}, {out / 'crb.png'}")
    return 0


__all__ = ["main", "run_trial", "summarise"]
