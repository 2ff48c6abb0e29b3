"""Choosing N configurations from a candidate set: I-optimal and D-optimal designs.

The information of a design is ``M = sum_c J_c^T J_c`` over its configurations (:mod:`information`;
each ``J_c`` has m = 6 rows per measured frame, so adding one is a rank-m update). Two criteria:

- **I-optimal** (integrated variance over the task region): minimise ``trace(A M^-1)`` with ``A``
  the task region's sensitivity (:attr:`~information.TaskSensitivity.A_p`): the predicted mean
  squared held-out position error itself (:mod:`prediction`).
- **D-optimal** (FIGAROH's choice): maximise ``log det M``.

Algorithm (the same for both): **greedy** forward selection from the required configurations (the
one-joint protocol's ``q0``), adding the candidate of largest gain (or a given start design, e.g.
the paper's protocol), then **Fedorov exchange**
passes: each chosen configuration is in turn removed and replaced by the candidate that improves
the criterion most, while any swap improves it (at most ``max_passes`` = 5 passes). Gains use the
Woodbury identity on the rank-m update, for all candidates at once: with ``S = I + J M^-1 J^T``,

    trace(A M^-1) - trace(A (M + J^T J)^-1) = trace(S^-1 J M^-1 A M^-1 J^T)
    log det(M + J^T J) - log det M           = log det S

``M`` is re-inverted at every step (P is small) rather than updated, so no rounding accumulates. A
ridge ``delta I`` (1e-9 of the mean candidate information's scale) makes the first steps, before
the design determines every parameter, well defined. Each candidate is chosen at most once.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import ConfigurationError

Array = NDArray[np.float64]

CRITERIA = ("I", "D")
RIDGE = 1e-9  # [-]: of the mean candidate information's trace per parameter
IMPROVEMENT_TOL = 1e-9  # [-]: relative improvement an exchange must bring
MAX_PASSES = 5


@dataclass
class Selection:
    """A design chosen from the candidates.

    Attributes:
        indices: Candidate indices, required ones first, shape (N,).
        value: Final criterion: ``trace(A M^-1)`` (I) or ``-log det M`` (D).
        greedy_values: The criterion after each greedy step (the greedy curve vs N).
        swaps: Exchanges accepted.
        passes: Exchange passes run.
    """

    indices: NDArray[np.int64]
    value: float
    greedy_values: list[float]
    swaps: int
    passes: int


def _value(M: Array, A: Array | None, criterion: str) -> float:
    if criterion == "I":
        assert A is not None
        return float(np.trace(np.linalg.solve(M, A)))
    sign, logdet = np.linalg.slogdet(M)
    return float(-logdet) if sign > 0 else float("inf")


def _gains(Minv: Array, Jc: Array, A: Array | None, criterion: str) -> Array:
    """Decrease of the criterion when each candidate is added to a design of inverse information ``Minv``."""
    m = Jc.shape[1]
    JM = Jc @ Minv  # broadcast matmul: faster than one large gemm when BLAS threads compete
    S = np.eye(m) + JM @ np.swapaxes(Jc, 1, 2)
    if criterion == "D":
        sign, logdet = np.linalg.slogdet(S)
        return np.where(sign > 0, logdet, -np.inf)
    assert A is not None
    JMA = JM @ A
    T = JMA @ np.swapaxes(JM, 1, 2)
    return np.trace(np.linalg.solve(S, T), axis1=1, axis2=2)


def select(
    Jc: Array,
    n: int,
    *,
    criterion: str = "I",
    A: Array | None = None,
    required: Sequence[int] = (),
    exchange: bool = True,
    max_passes: int = MAX_PASSES,
    stop_below: float | None = None,
    start: Sequence[int] | None = None,
) -> Selection:
    """Choose ``n`` of the candidates (greedy, then Fedorov exchange).

    Args:
        Jc: Weighted Jacobian rows of each candidate, shape (K, m, P).
        n: Configurations to choose (including the required ones).
        criterion: ``"I"`` (minimise ``trace(A M^-1)``) or ``"D"`` (maximise ``log det M``).
        A: The task region's sensitivity, shape (P, P) (``"I"`` only).
        required: Candidates every design contains (never exchanged out).
        exchange: Run the exchange passes after the greedy selection.
        max_passes: Largest number of exchange passes.
        stop_below: Stop the greedy selection as soon as the criterion is at most this (then
            fewer than ``n`` configurations may be chosen).
        start: Start the exchange from this design (``n`` distinct candidates including the
            required ones) instead of the greedy one.

    Raises:
        ConfigurationError: Unknown criterion, ``n`` out of range, missing ``A``.
    """
    if criterion not in CRITERIA:
        raise ConfigurationError(f"design criterion must be one of {CRITERIA}, got {criterion!r}")
    if criterion == "I" and A is None:
        raise ConfigurationError("the I-optimal criterion needs the task region's sensitivity A")
    K, _, P = Jc.shape
    req = [int(i) for i in dict.fromkeys(required)]
    if not len(req) <= n <= K:
        raise ConfigurationError(
            f"cannot choose {n} configurations from {K} candidates with {len(req)} required"
        )
    info = np.einsum("kmp,kmq->kpq", Jc, Jc)
    delta = RIDGE * float(np.trace(info.mean(axis=0))) / P
    chosen = list(req)
    if start is not None:
        chosen += [int(i) for i in dict.fromkeys(start) if int(i) not in req]
        if len(chosen) != n:
            raise ConfigurationError(
                f"the start design has {len(chosen)} distinct configurations, not {n}"
            )
    M = delta * np.eye(P) + info[chosen].sum(axis=0)
    taken = np.zeros(K, dtype=bool)
    taken[chosen] = True
    history: list[float] = []
    while len(chosen) < n:
        g = _gains(np.linalg.inv(M), Jc, A, criterion)
        g[taken] = -np.inf
        c = int(np.argmax(g))
        chosen.append(c)
        taken[c] = True
        M = M + info[c]
        history.append(_value(M, A, criterion))
        if stop_below is not None and history[-1] <= stop_below:
            break
    value = _value(M, A, criterion)
    swaps = passes = 0
    while exchange and passes < max_passes:
        passes += 1
        improved = False
        for pos in range(len(req), len(chosen)):
            old = chosen[pos]
            M_minus = M - info[old]
            g = _gains(np.linalg.inv(M_minus), Jc, A, criterion)
            g[taken] = -np.inf  # includes ``old``: putting it back changes nothing
            c = int(np.argmax(g))
            if not np.isfinite(g[c]):
                continue
            new_value = _value(M_minus + info[c], A, criterion)
            if new_value < value - IMPROVEMENT_TOL * abs(value):
                chosen[pos] = c
                taken[old], taken[c] = False, True
                M = M_minus + info[c]
                value = new_value
                swaps += 1
                improved = True
        if not improved:
            break
    return Selection(np.array(chosen, dtype=np.int64), value, history, swaps, passes)


__all__ = ["CRITERIA", "MAX_PASSES", "RIDGE", "Selection", "select"]
