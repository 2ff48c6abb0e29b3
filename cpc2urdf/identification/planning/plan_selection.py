"""Plan a stage-1 experiment: candidates the rig can measure, optimal designs, the curve vs N.

:func:`make_plan` answers the calibration engineer's three questions for a measuring setup
(:mod:`measuring`) and a task region:

1. which configurations: N chosen from a seeded candidate set (uniform in the calibration ranges,
   or, with ``one_joint``, ``q0`` plus each joint's sweep values, the structure the closed form
   needs) by greedy selection and Fedorov exchange (:mod:`optimal`) minimising the predicted
   held-out position error over the task region (I-optimal); candidates the rig cannot measure
   (a circle outside an image, hidden by a plate, or a plate more than 70 deg off face-on) are
   dropped first, so every planned configuration is measurable; where N = joints M + 1 the
   exchange is also started from the paper's protocol (when the rig sees all of it) and the better
   design kept;
2. how good: the predicted error of the plan (:mod:`prediction`), and the same for the D-optimal
   design (same candidates and algorithm, ``log det`` criterion) and the paper's
   one-joint-at-a-time protocol at equal N (N = n M + 1);
3. how many: with ``target_error``, the smallest N whose I-optimal plan predicts at most that RMS
   position error; the curve of predicted error vs N per strategy.

Example::

    setup = measuring_setup(load_robot("iis_head").nominal_model())
    result = make_plan(setup, n=19, q_task=task_configurations(setup))
    result.q, result.prediction.position_rms, result.curve
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cpc2urdf.errors import ConfigurationError
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.planning.information import StereoPoseMeasurement
from cpc2urdf.identification.planning.measuring import MeasuringSetup
from cpc2urdf.identification.planning.optimal import select
from cpc2urdf.identification.planning.prediction import (
    Prediction,
    chart_and_task,
    predict_from_jacobian,
)
from cpc2urdf.identification.simulation.design import protocol_configurations, random_configurations

Array = NDArray[np.float64]

STRATEGIES = ("I-optimal", "D-optimal", "protocol")
DEFAULT_CANDIDATES = 500
DEFAULT_TASK = 200
TASK_SEED = 1  # the task sample's own stream (the candidates use the plan's seed)
MAX_TARGET_N = 400  # largest plan --target-error searches
CURVE_M = (2, 3, 5, 9)  # protocol sizes the curve compares at (M = 9: the paper's choice)


@dataclass
class Candidates:
    """Configurations a plan may choose from, all measurable by the rig.

    Attributes:
        q: Shape (K, n) [m]/[rad].
        labels: One per configuration.
        required: Indices every plan contains (``q0`` of a one-joint plan).
        dropped: Candidates dropped because the rig cannot measure them.
    """

    q: Array
    labels: list[str]
    required: list[int]
    dropped: int


@dataclass
class CurvePoint:
    """Predicted errors of one strategy's plan of N configurations."""

    strategy: str
    n: int
    position_rms: float
    orientation_rms: float


@dataclass
class PlanResult:
    """A plan and what it is predicted to give.

    Attributes:
        q: The planned configurations, shape (N, n) [m]/[rad].
        labels: One per configuration.
        strategy: ``"I-optimal"`` (or the strategy asked for).
        one_joint: Whether the plan keeps the one-joint-at-a-time structure.
        prediction: Its predicted accuracy.
        curve: Predicted errors vs N per strategy.
        candidates: The candidate set.
        target_error: The requested RMS position error [m], if any.
    """

    q: Array
    labels: list[str]
    strategy: str
    one_joint: bool
    prediction: Prediction
    curve: list[CurvePoint] = field(default_factory=list)
    candidates: Candidates | None = None
    target_error: float | None = None


def task_configurations(
    setup: MeasuringSetup,
    region: str | ArrayLike = "calibration",
    *,
    n: int = DEFAULT_TASK,
    seed: int = TASK_SEED,
) -> Array:
    """The task region's configurations: ``"calibration"`` (uniform in the calibration ranges),
    ``"limits"`` (uniform within the joint limits), or explicit configurations (K, n) [m]/[rad]."""
    s = setup.nominal.structure
    if isinstance(region, str):
        if region == "calibration":
            r = setup.ranges
        elif region == "limits":
            r = np.column_stack([s.lower, s.upper])
        else:
            raise ConfigurationError(
                f"task region must be 'calibration', 'limits' or configurations, got {region!r}"
            )
        return random_configurations(r, n, np.random.default_rng(seed))
    q = np.atleast_2d(np.asarray(region, dtype=float))
    if q.shape[1] != s.n_joints or not np.all(np.isfinite(q)):
        raise ConfigurationError(
            f"task configurations must be finite, {s.n_joints} values each; got shape {q.shape}"
        )
    return q


def candidate_configurations(
    setup: MeasuringSetup,
    n: int = DEFAULT_CANDIDATES,
    *,
    seed: int = 0,
    one_joint: bool = False,
    grid: bool = False,
) -> Candidates:
    """The candidate set, without the configurations the rig cannot measure.

    Args:
        setup: The measuring setup.
        n: About how many candidates (before the visibility filter).
        seed: Seed of the random candidates.
        one_joint: ``q0`` (the middle of the ranges, required) and, per joint, ``ceil(n / joints)``
            values evenly spread over its calibration range with the others at ``q0``.
        grid: A full grid of ``floor(n ** (1 / joints))`` (at least 2) values per joint instead of
            random configurations (ignored with ``one_joint``).

    Raises:
        ConfigurationError: ``n < 1``, or the rig cannot measure ``q0`` of a one-joint plan.
    """
    if n < 1:
        raise ConfigurationError(f"the candidate set needs at least 1 configuration, got {n}")
    s = setup.nominal.structure
    r = setup.ranges
    if one_joint:
        per = max(2, math.ceil(n / s.n_joints))
        q, labels = protocol_configurations(r, per, s.joint_names)
    elif grid:
        per = max(2, int(math.floor(n ** (1.0 / s.n_joints) + 1e-9)))
        axes = [np.linspace(lo, hi, per) for lo, hi in r]
        q = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, s.n_joints)
        labels = [f"grid {i}" for i in range(len(q))]
    else:
        q = random_configurations(r, n, np.random.default_rng(seed))
        labels = [f"candidate {i}" for i in range(len(q))]
    ok = setup.measurable(q)
    if one_joint and not ok[0]:
        raise ConfigurationError(
            "the rig cannot measure q0 (the middle of the calibration ranges): "
            + "; ".join(setup.problems(q[:1], ["q0"])[:2])
        )
    keep = np.flatnonzero(ok)
    return Candidates(
        q[keep], [labels[i] for i in keep], [0] if one_joint else [], int(len(q) - len(keep))
    )


class Planner:
    """The candidates' information and the task region's sensitivity, computed once."""

    def __init__(self, setup: MeasuringSetup, candidates: Candidates, q_task: ArrayLike) -> None:
        if len(candidates.q) == 0:
            raise ConfigurationError("the rig measures none of the candidate configurations")
        self.setup = setup
        self.candidates = candidates
        self.measurement = setup.measurement()
        self.q_task = np.atleast_2d(np.asarray(q_task, dtype=float))
        self.chart, self.task, self.targets = chart_and_task(setup, self.measurement, self.q_task)
        self.Jc = self._jacobian(candidates.q)

    def _jacobian(self, q: Array) -> Array:
        return self.measurement.weighted_jacobian(self.chart, q)  # type: ignore[arg-type]

    def predict(self, q: ArrayLike) -> Prediction:
        qq = np.atleast_2d(np.asarray(q, dtype=float))
        J = self._jacobian(qq).reshape(-1, self.chart.n_params)
        m, chart = self.measurement, self.chart
        pipe = (
            m.pipeline(chart, qq)
            if isinstance(m, StereoPoseMeasurement) and isinstance(chart, Parametrization)
            else None
        )
        p = predict_from_jacobian(
            J, chart, self.task, self.targets, self.setup.sigma_t, self.setup.sigma_r, pipeline=pipe
        )
        p.n_configurations = len(qq)
        return p

    def design(self, strategy: str, n: int, *, exchange: bool = True) -> tuple[Array, list[str]]:
        """The configurations of ``strategy`` with ``n`` configurations.

        Raises:
            ConfigurationError: Unknown strategy; the protocol at an ``n`` that is not ``joints M + 1``;
                more configurations than candidates.
        """
        s = self.setup.nominal.structure
        if strategy == "protocol":
            M, rest = divmod(n - 1, s.n_joints)
            if rest or M < 2:
                raise ConfigurationError(
                    f"the paper's protocol has {s.n_joints} M + 1 configurations (M >= 2), not {n}"
                )
            return protocol_configurations(self.setup.ranges, M, s.joint_names)
        if strategy not in STRATEGIES:
            raise ConfigurationError(f"strategy must be one of {STRATEGIES}, got {strategy!r}")
        if n > len(self.candidates.q):
            raise ConfigurationError(
                f"{n} configurations asked for, but the rig measures only {len(self.candidates.q)} candidates "
                "(ask for more candidates)"
            )
        criterion = "I" if strategy == "I-optimal" else "D"
        req = self.candidates.required
        sel = select(
            self.Jc, n, criterion=criterion, A=self.task.A_p, required=req, exchange=exchange
        )
        q_all, labels_all = self.candidates.q, self.candidates.labels
        # Exchange is a local search: also start it from the paper's protocol (added to the
        # candidates) where N = joints M + 1, and keep the better, so that an optimal plan is never
        # predicted worse than the protocol it is compared with.
        M, rest = divmod(n - 1, s.n_joints)
        if exchange and not rest and M >= 2:
            q_p, lab_p = protocol_configurations(self.setup.ranges, M, s.joint_names)
            if self.candidates.required:  # one-joint: the candidates' q0 is the protocol's
                q_p, lab_p = q_p[1:], lab_p[1:]
            if self.setup.measurable(q_p).all():
                Jc = np.concatenate([self.Jc, self._jacobian(q_p)])
                first = len(self.Jc)
                alt = select(
                    Jc,
                    n,
                    criterion=criterion,
                    A=self.task.A_p,
                    required=req,
                    start=[*req, *range(first, first + len(q_p))],
                )
                if alt.value < sel.value:
                    sel = alt
                    q_all = np.vstack([q_all, q_p])
                    labels_all = [*labels_all, *lab_p]
        idx = sel.indices
        return q_all[idx], [labels_all[i] for i in idx]

    def smallest_n(self, target: float, *, n_max: int = MAX_TARGET_N) -> int:
        """Smallest N whose I-optimal plan predicts an RMS position error <= ``target`` [m].

        Raises:
            ConfigurationError: Not reachable with ``n_max`` configurations (or all candidates).
        """
        n_max = min(n_max, len(self.candidates.q))
        n0 = len(self.candidates.required)
        sel = select(
            self.Jc,
            n_max,
            criterion="I",
            A=self.task.A_p,
            required=self.candidates.required,
            exchange=False,
            stop_below=target**2,
        )
        values = np.sqrt(np.maximum(sel.greedy_values, 0.0))
        hit = np.flatnonzero(values <= target)
        if hit.size == 0:
            raise ConfigurationError(
                f"a predicted RMS position error of {target * 1e3:.4g} mm is not reached with {n_max} configurations "
                f"(best {values[-1] * 1e3:.4g} mm): lower the noise, widen the ranges or ask for less"
            )
        n = n0 + int(hit[0]) + 1  # greedy is an upper bound; the exchange may do with fewer
        while n - 1 > max(n0, 1):
            q, _ = self.design("I-optimal", n - 1)
            if self.predict(q).position_rms > target:
                break
            n -= 1
        return n

    def curve(self, ns: Sequence[int], strategies: Sequence[str] = STRATEGIES) -> list[CurvePoint]:
        """Predicted errors of each strategy's plan at each N (the protocol where N = joints M + 1)."""
        out = []
        nj = self.setup.nominal.structure.n_joints
        for strategy in strategies:
            for n in ns:
                if strategy == "protocol" and ((n - 1) % nj or (n - 1) // nj < 2):
                    continue
                if strategy != "protocol" and n > len(self.candidates.q):
                    continue
                q, _ = self.design(strategy, n)
                p = self.predict(q)
                out.append(CurvePoint(strategy, n, p.position_rms, p.orientation_rms))
        return out


def make_plan(
    setup: MeasuringSetup,
    *,
    n: int | None = None,
    target_error: float | None = None,
    q_task: ArrayLike | None = None,
    one_joint: bool = False,
    n_candidates: int = DEFAULT_CANDIDATES,
    seed: int = 0,
    grid: bool = False,
    curve_ns: Sequence[int] | None = None,
) -> PlanResult:
    """The I-optimal plan of ``n`` configurations, or of the fewest reaching ``target_error``.

    Args:
        setup: The measuring setup.
        n: Configurations to plan.
        target_error: Instead of ``n``: the RMS position error to reach over the task region [m].
        q_task: Task configurations (default: :func:`task_configurations` of the calibration ranges).
        one_joint: Keep the one-joint-at-a-time structure (``q0`` plus single-joint moves).
        n_candidates: Candidate set size (before the visibility filter).
        seed: Seed of the candidates.
        grid: Grid candidates instead of random ones.
        curve_ns: N values of the curve (default: the protocol's ``joints M + 1`` for M in :data:`CURVE_M` and
            the plan's N).

    Raises:
        ConfigurationError: Neither or both of ``n`` and ``target_error``, bad values, an
            unreachable target.
    """
    if (n is None) == (target_error is None):
        raise ConfigurationError(
            "give either the number of configurations or the target error, not both"
        )
    if n is not None and n < 1:
        raise ConfigurationError(f"the number of configurations must be >= 1, got {n}")
    if target_error is not None and not (math.isfinite(target_error) and target_error > 0):
        raise ConfigurationError(f"the target error must be a positive number, got {target_error}")
    q_task = task_configurations(setup) if q_task is None else task_configurations(setup, q_task)
    cands = candidate_configurations(setup, n_candidates, seed=seed, one_joint=one_joint, grid=grid)
    planner = Planner(setup, cands, q_task)
    if target_error is not None:
        n = planner.smallest_n(target_error)
    assert n is not None
    q, labels = planner.design("I-optimal", n)
    nj = setup.nominal.structure.n_joints
    ns = sorted(set(curve_ns if curve_ns is not None else [nj * M + 1 for M in CURVE_M]) | {n})
    return PlanResult(
        q,
        labels,
        "I-optimal",
        one_joint,
        planner.predict(q),
        planner.curve(ns),
        cands,
        target_error,
    )


__all__ = [
    "DEFAULT_CANDIDATES",
    "DEFAULT_TASK",
    "STRATEGIES",
    "Candidates",
    "CurvePoint",
    "PlanResult",
    "Planner",
    "candidate_configurations",
    "make_plan",
    "task_configurations",
]
