"""Which parameters do the data determine? Rank, singular values and null space of the Jacobian.

The weighted Jacobian ``J`` (residuals divided by their noise sigma, see :mod:`refine`) is
column-scaled to unit column norms before its SVD, so that metres and radians compare fairly
(``J D^-1``, ``D = diag(|J_:,i|)``): the condition number is then that of the problem a
least-squares solver actually sees, and a relative singular value below :data:`RANK_TOL` marks a
direction the data cannot see at all (a joint that never moved, a frame never measured). Such
directions are reported by name, as the parameters that take part in them and, when the data
show why, the reason; :class:`IdentifiabilityWarning` is issued. They are never silently given
a number: :mod:`uncertainty` marks their standard deviation as undetermined.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from cpc2urdf.transforms import Array

# A direction whose singular value, relative to the largest of the column-scaled weighted
# Jacobian, is below this is not determined by the data (exact rank deficiency lands at ~1e-15).
RANK_TOL = 1e-9  # [-]
ZERO_COLUMN = 1e-10  # [-] a Jacobian column this small against the largest is rounding
# Above this condition number of the column-scaled Jacobian the estimate is determined only in
# principle: a warning says which combination is weakest.
ILL_CONDITIONED = 1e6  # [-]
# A parameter "takes part" in a null direction when its share of the null space exceeds this.
PARTICIPATION_TOL = 0.05  # [-]


class IdentifiabilityWarning(UserWarning):
    """The data cannot determine some parameters (or determine them only poorly)."""


@dataclass
class IdentifiabilityReport:
    """Rank analysis of a weighted Jacobian.

    Attributes:
        names: Parameter names, shape (P,).
        singular_values: Of the column-scaled weighted Jacobian, descending, shape (P,).
        column_norms: ``|J_:,i|``: sensitivity of the weighted residuals to each parameter
            [1/rad] or [1/m].
        rank: Numerical rank (relative tolerance :data:`RANK_TOL`).
        condition_number: ``s_max / s_min`` of the column-scaled Jacobian (inf if rank-deficient).
        null_space: Unidentifiable directions in parameter coordinates (unit-normalised columns
            of the *unscaled* parameters), shape (P, P - rank).
        undetermined: Names of the parameters that take part in a null direction.
        reasons: Owner (joint/frame) -> why the data cannot determine it, where known.
        warnings: Human-readable findings (also issued as :class:`IdentifiabilityWarning`).
    """

    names: tuple[str, ...]
    singular_values: Array
    column_norms: Array
    rank: int
    condition_number: float
    null_space: Array
    undetermined: list[str] = field(default_factory=list)
    reasons: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    @property
    def n_params(self) -> int:
        return len(self.names)

    @property
    def full_rank(self) -> bool:
        return self.rank == self.n_params

    def summary(self) -> str:
        """A few lines for a terminal."""
        s = self.singular_values
        lines = [
            f"parameters: {self.n_params}, numerical rank: {self.rank}, condition number "
            f"(column-scaled): {self.condition_number:.3g}",
            f"singular values (column-scaled): max {s[0]:.3g}, min {s[-1]:.3g}",
        ]
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def to_json(self) -> dict[str, object]:
        """A JSON-ready dict (model files, ``--json`` outputs)."""
        return {
            "n_params": self.n_params,
            "rank": self.rank,
            "condition_number": None
            if not np.isfinite(self.condition_number)
            else self.condition_number,
            "singular_values": [float(v) for v in self.singular_values],
            "undetermined": list(self.undetermined),
            "warnings": list(self.warnings),
        }


def analyze_jacobian(
    J: ArrayLike,
    names: Sequence[str],
    *,
    reasons: Mapping[str, str] | None = None,
    warn: bool = True,
) -> IdentifiabilityReport:
    """Numerical rank, singular values, condition number and named null space of ``J``.

    Args:
        J: Weighted Jacobian of the residuals, shape (m, P) (each residual divided by its sigma).
        names: Parameter names ``"<owner>.<param>"``, length P.
        reasons: Owner -> a data-based reason it is undetermined (see :func:`data_reasons`);
            quoted in the warnings for owners that take part in a null direction.
        warn: Issue :class:`IdentifiabilityWarning` for each finding.

    Returns:
        The report. Never raises on rank deficiency: that is what it reports.
    """
    J = np.asarray(J, dtype=float)
    names = tuple(names)
    P = J.shape[1]
    if len(names) != P:
        raise ValueError(f"{len(names)} names for a Jacobian with {P} columns")
    norms = np.linalg.norm(J, axis=0)
    scale, s, Vt = scaled_svd(J)
    s_max = s[0] if s.size and s[0] > 0 else 1.0
    null = s / s_max < RANK_TOL
    rank = int(np.sum(~null))
    V0s = Vt[null].T  # null directions in scaled coordinates, (P, k)
    cond = float(s[0] / s[-1]) if rank == P and s[-1] > 0 else float("inf")
    # Back to parameter units (x = D^-1 x_scaled), unit-normalised per direction.
    V0 = V0s / scale[:, None]
    V0 = V0 / np.maximum(np.linalg.norm(V0, axis=0), 1e-300) if V0.size else V0
    participation = np.linalg.norm(V0s, axis=1) if V0s.size else np.zeros(P)
    undetermined = [n for n, p in zip(names, participation, strict=True) if p > PARTICIPATION_TOL]
    reasons = dict(reasons or {})
    findings: list[str] = []
    if rank < P:
        owners = _group_by_owner(undetermined)
        involved = "; ".join(f"{o} ({', '.join(ps)})" for o, ps in owners.items())
        why = [f"{o}: {reasons[o]}" for o in owners if o in reasons]
        msg = (
            f"the data determine only {rank} of {P} parameters: {P - rank} combination(s) are "
            f"free, involving {involved}"
        )
        if why:
            msg += " — because " + "; ".join(why)
        msg += ". Their values are kept from the start model; their uncertainty is reported as undetermined."
        findings.append(msg)
        for k in range(V0.shape[1]):
            findings.append("free combination: " + _describe(V0[:, k], names))
    elif cond > ILL_CONDITIONED:
        weakest = Vt[-1] / scale
        weakest /= np.linalg.norm(weakest)
        findings.append(
            f"poorly determined: condition number {cond:.3g} > {ILL_CONDITIONED:.0e}; the weakest "
            f"combination is {_describe(weakest, names)}"
        )
    if rank == P:  # the data look thin for an owner, yet the Jacobian sees it: say so
        findings += [
            f"{owner}: {why} (yet the Jacobian has full rank)" for owner, why in reasons.items()
        ]
    if warn:
        for f in findings:
            warnings.warn(f, IdentifiabilityWarning, stacklevel=2)
    return IdentifiabilityReport(names, s, norms, rank, cond, V0, undetermined, reasons, findings)


def scaled_svd(J: ArrayLike) -> tuple[Array, Array, Array]:
    """``(d, s, Vt)``: the SVD ``J / d = U diag(s) Vt`` of ``J`` (m, P) with its columns scaled to
    unit norm by ``d`` (P,), so that metres and radians compare fairly. A column at rounding
    level against the largest (:data:`ZERO_COLUMN`; a joint that moves every measured frame alike
    when only relative poses are seen) is zero, ``d = 1``: scaled to unit length its rounding
    would pass for information."""
    J = np.asarray(J, dtype=float)
    norms = np.linalg.norm(J, axis=0)
    zero = norms <= ZERO_COLUMN * norms.max(initial=0.0)
    d = np.where(zero, 1.0, norms)
    _, s, Vt = np.linalg.svd(triangular_factor(np.where(zero, 0.0, J / d)))
    return d, s, Vt


def triangular_factor(A: ArrayLike) -> Array:
    """``R`` of a Householder QR of ``A`` (m >= P), shape (P, P): same singular values and right
    singular vectors as ``A``, so the SVD of ``R`` is that of ``A``.

    Written with einsum on purpose: LAPACK's QR/SVD of a 660 x 32 matrix takes 0.1-0.3 s when
    OpenBLAS threads compete with other processes for the cores (measured on the 2-core CI
    machine), this loop takes ~1 ms whatever the load, and Householder QR is backward stable.
    """
    R = np.array(A, dtype=float)
    m, P = R.shape
    if m < P:
        R = np.vstack([R, np.zeros((P - m, P))])
        m = P
    for k in range(P):
        x = R[k:, k]
        alpha = -np.copysign(np.sqrt(np.einsum("i,i->", x, x)), x[0] if x[0] != 0 else 1.0)
        v = x.copy()
        v[0] -= alpha
        vv = np.einsum("i,i->", v, v)
        if vv == 0.0:
            continue
        R[k:, k:] -= np.outer(v, np.einsum("i,ij->j", v, R[k:, k:]) * (2.0 / vv))
    return np.triu(R[:P])


def _group_by_owner(names: Sequence[str]) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for n in names:
        owner, _, p = n.rpartition(".")
        out.setdefault(owner, []).append(p)
    return out


def _describe(v: Array, names: Sequence[str], keep: float = 0.1) -> str:
    """``0.71*tilt.l_x - 0.70*vergence_left.l_x + ...`` for the larger entries of ``v``."""
    order = np.argsort(-np.abs(v))
    big = [i for i in order if abs(v[i]) >= keep * abs(v[order[0]])][:8]
    terms = [f"{v[i]:+.2f}*{names[i]}" for i in big]
    more = int(np.sum(np.abs(v) >= keep * abs(v[order[0]]))) - len(big)
    return " ".join(terms) + (f" (+{more} smaller terms)" if more > 0 else "")


def data_reasons(
    parametrization: object, q: ArrayLike, has_pose: Mapping[str, ArrayLike]
) -> dict[str, str]:
    """Plain reasons, read off the data, why some joints or frames cannot be identified.

    Args:
        parametrization: A :class:`~cpc2urdf.identification.kinematics.parametrization.Parametrization`.
        q: Joint readings of the records, shape (N, n).
        has_pose: Frame -> which records measured it, shape (N,) booleans.

    Returns:
        Owner name -> reason, e.g. ``{"tilt": "joint 'tilt' has one distinct reading (0.52 rad)
        in the 55 records that see its frames: it never moved"}``.
    """
    from cpc2urdf.identification.kinematics.parametrization import Parametrization

    assert isinstance(parametrization, Parametrization)
    p = parametrization
    s = p.reference.structure
    q = np.atleast_2d(np.asarray(q, dtype=float))
    seen = {f: np.asarray(has_pose.get(f, np.zeros(len(q), bool)), dtype=bool) for f in p.frames}
    out: dict[str, str] = {}
    for f in p.frames:
        if not seen[f].any():
            out[f] = f"frame {f!r} has no measured pose"
    for j in p.joints:
        below = [f for f in p.frames if j in s.path_to(f)]
        rows = np.zeros(len(q), dtype=bool)
        for f in below:
            rows |= seen[f]
        values = np.unique(np.round(q[rows, s.joint_index(j)], 12))
        unit = "rad" if s.joint(j).type == "revolute" else "m"
        if len(values) < 2:
            at = f" ({values[0]:.6g} {unit})" if len(values) else ""
            out[j] = (
                f"joint {j!r} has {len(values)} distinct reading{'' if len(values) == 1 else 's'}"
                f"{at} in the {int(rows.sum())} records that see {', '.join(below)}: it never moved"
            )
    return out


__all__ = [
    "ILL_CONDITIONED",
    "RANK_TOL",
    "ZERO_COLUMN",
    "IdentifiabilityReport",
    "IdentifiabilityWarning",
    "analyze_jacobian",
    "data_reasons",
    "scaled_svd",
    "triangular_factor",
]
