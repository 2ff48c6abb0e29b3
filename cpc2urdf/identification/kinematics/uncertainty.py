"""Parameter covariance of a refined model, and the predicted position uncertainty of its frames.

Covariance (first order, at the optimum). With the weighted Jacobian ``J`` (every residual divided
by its noise sigma, :mod:`refine`) the estimate's covariance is

    C = s^2 (J^T J)^+         in the local chart of the refined model (:mod:`parametrization`)

where ``s^2`` is either 1 (``scale="known"``: the noise sigmas are trusted; then ``C`` is the
Cramér-Rao bound for Gaussian noise of that covariance) or the a-posteriori variance factor
``s0^2 = |r|^2 / (m - rank)`` (``scale="a_posteriori"``: the sigmas only fix the relative weights
and the residuals set the overall level). The pseudo-inverse is taken on the identifiable
subspace only; parameters that take part in an undetermined direction get ``std = NaN``
(``null`` in files), never a number.

Propagation: the position of frame f at configuration q moves by ``dp = G x`` for a small
parameter change ``x`` (``G`` = rows 0-2 of :meth:`Parametrization.pose_jacobian`), so its
covariance is ``G C G^T`` and its standard deviation ``sqrt(trace(G C G^T))`` [m] (the RMS of the
Euclidean position error). If ``G`` sees an undetermined direction the prediction is
undetermined (``inf``).

Cramér-Rao bound (:func:`cramer_rao_covariance`): ``C = (J^T J)^-1`` with ``J`` the same weighted
Jacobian evaluated at the *true* robot on noise-free poses, in the true robot's own chart; what an
efficient estimator (the refinement) reaches, used by ``cpc2urdf study crb`` and the tests.

Model files store this under the ``"uncertainty"`` section (SI units, parameters named), so that
:func:`predicted_position_std` works on any loaded model that carries it.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
from numpy.typing import ArrayLike

from cpc2urdf.identification.kinematics.identifiability import RANK_TOL, scaled_svd
from cpc2urdf.identification.kinematics.parametrization import Parametrization
from cpc2urdf.identification.kinematics.problem import IdentificationProblem
from cpc2urdf.model import CPCModel
from cpc2urdf.model_metadata import Covariance, NoUncertaintyError
from cpc2urdf.transforms import Array

SCALES = ("known", "a_posteriori")
# A configuration's position Jacobian "sees" a null direction when its response to it exceeds
# this fraction of its response to a typical identifiable direction.
NULL_VISIBILITY_TOL = 1e-6  # [-]


def covariance_from_jacobian(
    J: ArrayLike,
    parametrization: Parametrization,
    *,
    residuals: ArrayLike,
    sigma_t: float,
    sigma_r: float,
    scale: str = "known",
) -> Covariance:
    """Covariance of the parameters from the weighted Jacobian at the optimum.

    Args:
        J: Weighted Jacobian at the optimum, in ``parametrization``'s chart, shape (m, P).
        parametrization: Chart centred on the refined model (so ``C`` is about that model).
        residuals: Weighted residuals at the optimum, shape (m,) (for the variance factor).
        sigma_t: Translation noise [m] behind the weights.
        sigma_r: Rotation-angle noise [rad] behind the weights.
        scale: ``"known"`` (trust the sigmas: the Cramér-Rao bound) or ``"a_posteriori"``.
    """
    if scale not in SCALES:
        raise ValueError(f"scale must be one of {SCALES}, got {scale!r}")
    J = np.asarray(J, dtype=float)
    r = np.asarray(residuals, dtype=float)
    d, s, Vt = scaled_svd(J)
    keep = s / (s[0] if s[0] > 0 else 1.0) >= RANK_TOL
    rank = int(keep.sum())
    # (J^T J)^+ restricted to the identifiable subspace, undoing the column scaling.
    Vk = Vt[keep].T / d[:, None]
    C = (Vk / s[keep] ** 2) @ Vk.T
    V0 = Vt[~keep].T / d[:, None]
    if V0.size:
        V0 = V0 / np.linalg.norm(V0, axis=0)
    dof = max(J.shape[0] - rank, 1)
    s0 = float(r @ r / dof)
    if scale == "a_posteriori":
        C = s0 * C
    return Covariance(
        parametrization.names,
        parametrization.units,
        parametrization.frames,
        0.5 * (C + C.T),
        V0,
        scale,
        s0,
        dof,
        float(sigma_t),
        float(sigma_r),
    )


def cramer_rao_covariance(
    truth: CPCModel, q: ArrayLike, frames: Sequence[str], sigma_t: float, sigma_r: float
) -> tuple[Parametrization, Array]:
    """Cramér-Rao covariance of the parameters of ``truth`` measured at configurations ``q``.

    ``C = (J^T J)^-1`` with ``J`` the weighted Jacobian of eq. (23) (:class:`IdentificationProblem`,
    Fig. 10 noise of ``sigma_t`` per translation entry and rotation angle ``sigma_r``, i.e.
    ``sigma_r / sqrt(3)`` per rotation-vector axis) at the true robot, every pose of every frame
    measured. It is the covariance of an efficient estimator under Gaussian noise of those second
    moments: the reference the refinement is compared with. ``J^T J`` must be invertible (the
    data determine every parameter of the chart).

    Args:
        truth: The true robot; the bound is about its own chart (gauge-aligned coordinates).
        q: Configurations [rad]/[m], shape (N, n) in ``structure.joint_names`` order.
        frames: Measured frames.
        sigma_t: Standard deviation of each measured translation entry [m].
        sigma_r: Standard deviation of the measured rotation error's angle [rad].

    Returns:
        ``(chart, C)``: the :class:`Parametrization` centred on ``truth`` (names, units) and the
        covariance of its P parameters, shape (P, P) [m^2, m rad, rad^2].
    """
    chart = Parametrization(truth, frames)
    q_arr = np.asarray(q, dtype=float)
    poses = truth.fk(q_arr, frames)
    use = {f: np.ones(len(q_arr), dtype=bool) for f in frames}
    J = IdentificationProblem(chart, q_arr, poses, use, sigma_t, sigma_r).jacobian(
        np.zeros(chart.n_params)
    )
    return chart, np.linalg.inv(J.T @ J)


def with_uncertainty(model: CPCModel, cov: Covariance) -> CPCModel:
    """A copy of ``model`` whose metadata carries ``cov`` (its ``"uncertainty"`` section)."""
    return model.with_params(metadata=model.metadata.replace(uncertainty=cov))


def covariance_of_model(model: CPCModel) -> Covariance:
    """The :class:`Covariance` a model (file) carries; :class:`NoUncertaintyError` if none."""
    cov = model.metadata.uncertainty
    if cov is None:
        raise NoUncertaintyError(
            f"model {model.structure.name!r} carries no 'uncertainty' section "
            "(identify it with --method refined)"
        )
    return cov


def position_covariance(
    model: CPCModel, cov: Covariance, q: ArrayLike, frames: Iterable[str] | None = None
) -> tuple[dict[str, Array], dict[str, Array]]:
    """Covariance of each frame's predicted origin at configurations ``q``.

    Args:
        model: The model ``cov`` belongs to (its own chart).
        cov: Its parameter covariance.
        q: Configurations [rad]/[m], shape (N, n) or (n,).
        frames: Frames to report (default: ``cov.frames``); must be among ``cov.frames``.

    Returns:
        ``(Sigma, determined)``: ``Sigma[f]`` of shape (N, 3, 3) [m^2]; ``determined[f]`` of
        shape (N,) booleans, False where the prediction depends on an undetermined direction.
    """
    p = Parametrization(model, cov.frames)
    if p.names != cov.names:
        raise NoUncertaintyError(
            f"uncertainty parameters {list(cov.names)[:4]}... do not match the model's chart "
            f"{list(p.names)[:4]}... (was the model edited after identification?)"
        )
    names = list(frames) if frames is not None else list(cov.frames)
    for f in names:
        if f not in cov.frames:
            raise NoUncertaintyError(
                f"frame {f!r} was not identified; uncertainty covers {list(cov.frames)}"
            )
    qq = model.structure.check_q(q)
    qq = np.atleast_2d(qq)
    _, D = p.pose_jacobian(np.zeros(p.n_params), qq)
    Sigma: dict[str, Array] = {}
    determined: dict[str, Array] = {}
    for f in names:
        G = D[f][:, :3, :]  # (N, 3, P)
        Sigma[f] = np.einsum("nip,pq,njq->nij", G, cov.matrix, G)
        if cov.null_space.size:
            seen = np.linalg.norm(G @ cov.null_space, axis=(1, 2))
            typical = np.linalg.norm(G, axis=(1, 2)) / np.sqrt(G.shape[2])  # per unit parameter
            determined[f] = seen <= NULL_VISIBILITY_TOL * typical
        else:
            determined[f] = np.ones(len(qq), dtype=bool)
    return Sigma, determined


def predicted_position_std(
    model: CPCModel,
    q: ArrayLike,
    frames: Sequence[str] | None = None,
    *,
    measurement_noise: bool = False,
) -> dict[str, Array]:
    """Predicted standard deviation of each identified frame's origin at configurations ``q``.

    This is the function ``cpc2urdf accuracy`` calls to put predicted next to observed errors.

    Args:
        model: A model carrying an ``"uncertainty"`` section (``identify --method refined``).
        q: Configurations [rad]/[m], shape (N, n) in ``structure.joint_names`` order, or (n,).
        frames: Frames to report (default: every identified frame).
        measurement_noise: Add the measuring system's own noise (``3 sigma_t^2``, the sigma the
            identification assumed): the expected error against *measured* held-out poses, as
            opposed to true ones (simulations).

    Returns:
        Frame -> ``sqrt(trace(Sigma_p) [+ 3 sigma_t^2])`` [m] (the RMS Euclidean position error
        expected from the identification), shape (N,); ``inf`` where the data did not determine it.

    Raises:
        NoUncertaintyError: The model has no usable uncertainty section.
    """
    cov = covariance_of_model(model)
    Sigma, determined = position_covariance(model, cov, q, frames)
    extra = (
        3.0 * cov.sigma_t**2 * (cov.variance_factor if cov.scale == "a_posteriori" else 1.0)
        if measurement_noise
        else 0.0
    )
    return {
        f: np.where(
            determined[f],
            np.sqrt(np.clip(np.trace(S, axis1=1, axis2=2), 0.0, None) + extra),
            np.inf,
        )
        for f, S in Sigma.items()
    }


__all__ = [
    "SCALES",
    "Covariance",
    "NoUncertaintyError",
    "covariance_from_jacobian",
    "covariance_of_model",
    "cramer_rao_covariance",
    "position_covariance",
    "predicted_position_std",
    "with_uncertainty",
]
