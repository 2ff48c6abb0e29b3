"""The default hand-eye solver: joint maximum likelihood, outliers dropped, unknown scale."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_handeye import EXACT, make_data

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.identification.handeye import solvers
from cpc2urdf.identification.handeye.axzb import solve_kronecker
from cpc2urdf.identification.handeye.likelihood import pose_residuals, solve_likelihood
from cpc2urdf.identification.handeye.solvers import DEFAULT_HANDEYE_METHOD, Gate, calibrate
from cpc2urdf.transforms import homogeneous, inverse, rotation_error, rotvec_from_matrix


def _noisy(rng: np.random.Generator, H: np.ndarray, C: np.ndarray, camera_depth: float = 3e-3):
    """Hand twist noise (0.5 mrad, 0.3 mm) and anisotropic camera noise (1 mrad; 0.5 mm across,
    ``camera_depth`` along the optical axis)."""
    n = len(H)
    dh = [
        homogeneous(Rotation.from_rotvec(v).as_matrix(), t)
        for v, t in zip(rng.normal(0, 5e-4, (n, 3)), rng.normal(0, 3e-4, (n, 3)), strict=True)
    ]
    dc = [
        homogeneous(Rotation.from_rotvec(v).as_matrix(), t)
        for v, t in zip(
            rng.normal(0, 1e-3, (n, 3)),
            rng.normal(0, 1, (n, 3)) * [5e-4, 5e-4, camera_depth],
            strict=True,
        )
    ]
    return H @ np.array(dh), np.array(dc) @ C


def _errors(X: np.ndarray, X_true: np.ndarray) -> tuple[float, float]:
    return float(rotation_error(X[:3, :3], X_true[:3, :3])), float(
        np.linalg.norm(X[:3, 3] - X_true[:3, 3])
    )


def test_default_is_the_likelihood() -> None:
    assert DEFAULT_HANDEYE_METHOD == "ml"


@pytest.mark.parametrize("n", [3, 8, 60])
def test_noise_free_recovery(n: int) -> None:
    X, Z, H, C = make_data(np.random.default_rng(n), n)
    fit = solve_likelihood(H, C)
    assert np.abs(fit.X - X).max() < EXACT and np.abs(fit.Z - Z).max() < EXACT
    assert fit.inliers.all()


@pytest.mark.slow
def test_covariance_predicts_the_error() -> None:
    """Camera depth noise 6x the lateral one, one geometry of 100 poses, 100 noise draws: the
    spread of X's error per component is what the solution's covariance states (the ratio's
    sampling error over 100 draws is 7 %, so 0.75-1.3 is a 3.5-sigma band)."""
    X, Z, H, C = make_data(np.random.default_rng(5), 100)
    dx, cov = [], []
    for seed in range(100):
        fit = solve_likelihood(*_noisy(np.random.default_rng(1000 + seed), H, C))
        R = X[:3, :3]
        dx.append(
            np.concatenate(
                [
                    rotvec_from_matrix((R.T @ fit.X[:3, :3])[None])[0],
                    R.T @ (fit.X[:3, 3] - X[:3, 3]),
                ]
            )
        )
        cov.append(np.diag(fit.covariance)[:6])
    ratio = np.sqrt(np.mean(np.square(dx), axis=0) / np.mean(cov, axis=0))
    assert np.all((ratio > 0.75) & (ratio < 1.3)), ratio


def test_beats_kronecker_on_anisotropic_noise() -> None:
    """Weighted by the estimated noise, the solution is closer than the unweighted closed form."""
    ml, kr = [], []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        X, Z, H, C = make_data(rng, 40)
        Hn, Cn = _noisy(rng, H, C)
        ml.append(_errors(solve_likelihood(Hn, Cn).X, X)[1])
        kr.append(_errors(solve_kronecker(Hn, inverse(Cn))[0], X)[1])
    assert np.median(ml) < np.median(kr)


def test_residual_is_zero_at_the_truth() -> None:
    X, Z, H, C = make_data(np.random.default_rng(3), 10)
    assert np.abs(pose_residuals(H, C, X, Z)).max() < 1e-12


@pytest.mark.parametrize("kind", ["random", "flip"])
def test_outliers_dropped_and_named(kind: str) -> None:
    """A third of the poses replaced (random poses, or the target turned 180 deg about its own
    x axis, a planar pose ambiguity's worst case): exactly those are dropped, and the answer is
    within one standard deviation of the answer without them."""
    rng = np.random.default_rng(7)
    X, Z, H, C = make_data(rng, 45)
    Hn, Cn = _noisy(rng, H, C)
    bad = rng.choice(45, 15, replace=False)
    clean = solve_likelihood(np.delete(Hn, bad, 0), np.delete(Cn, bad, 0))
    for k in bad:
        if kind == "random":
            Cn[k] = homogeneous(
                Rotation.random(random_state=int(k)).as_matrix(), Cn[k, :3, 3] * 1.3
            )
        else:
            Cn[k] = Cn[k] @ homogeneous(Rotation.from_euler("x", 0.6).as_matrix(), np.zeros(3))
    fit = solve_likelihood(Hn, Cn)
    assert set(np.flatnonzero(~fit.inliers)) == set(bad.tolist())
    dx = np.concatenate(
        [
            rotvec_from_matrix((clean.X[:3, :3].T @ fit.X[:3, :3])[None])[0],
            clean.X[:3, :3].T @ (fit.X[:3, 3] - clean.X[:3, 3]),
        ]
    )
    assert dx @ np.linalg.solve(clean.covariance[:6, :6], dx) < 1.0  # within one sigma
    labels = [f"shot {k}" for k in range(45)]
    result = calibrate(Hn, Cn, "ml", gate=Gate(labels=labels))
    warning = next(w for w in result.warnings if "dropped as outliers" in w)
    assert warning.startswith("15 of 45 poses dropped") and f"shot {sorted(bad)[0]}," in warning


def test_unknown_scale_recovered() -> None:
    """Target translations 2.5 times the metric ones: the scale and X recovered exactly."""
    X, Z, H, C = make_data(np.random.default_rng(11), 12)
    C[:, :3, 3] *= 2.5
    fit = solve_likelihood(H, C, estimate_scale=True)
    assert abs(fit.scale - 2.5) < 1e-9 and np.abs(fit.X - X).max() < EXACT
    result = calibrate(H, C, "ml", gate=Gate(), unknown_scale=True)  # the command's path
    assert np.abs(result.X - X).max() < EXACT and result.residual_translation.max() < 1e-9
    assert "target translations were 2.5 times the metric ones" in result.warnings
    with pytest.raises(DegenerateDataError, match="only ml estimates an unknown scale"):
        calibrate(H, C, "kronecker", unknown_scale=True)


def test_one_joint_gives_the_determined_part_and_names_the_rest() -> None:
    """All hand rotations about one axis: the default answers and names X's rotation about that
    axis as undetermined; what is determined is exact; the closed forms still refuse."""
    X, Z, _, _ = make_data(np.random.default_rng(0), 3)
    H = np.array(
        [
            homogeneous(Rotation.from_euler("z", a).as_matrix(), [0.3, 0.1, 0.5])
            for a in np.linspace(0.0, 2.0, 10)
        ]
    )
    C = inverse(X)[None] @ inverse(H) @ Z[None]
    result = calibrate(H, C, "ml", gate=Gate())
    words = next(w for w in result.warnings if w.startswith("undetermined by these poses"))
    about = json.loads(words.split("X's rotation about ")[1].split("]")[0] + "]")
    assert abs(np.dot(about, [0.0, 0.0, 1.0])) > 0.999  # the joint's axis, in the hand frame
    # determined: the camera's tilt to the axis and its distance from it
    assert abs(result.X[2, 2] - X[2, 2]) < 1e-9
    assert np.hypot(*result.X[:2, 3]) == pytest.approx(np.hypot(*X[:2, 3]), abs=1e-9)
    with pytest.raises(DegenerateDataError, match="parallel axes"):
        calibrate(H, C, "kronecker", gate=Gate())


def test_says_so_when_the_closed_forms_agree_elsewhere(monkeypatch: pytest.MonkeyPatch) -> None:
    """Clean noisy data: no word. A default 30 mm off what the closed forms agree on: a warning
    naming them, the distance and their spread."""
    rng = np.random.default_rng(4)
    X, Z, H, C = make_data(rng, 30)
    Hn, Cn = _noisy(rng, H, C)
    assert not any(w.startswith("ml is ") for w in calibrate(Hn, Cn, "ml").warnings)
    real = solvers.solve_likelihood

    def shifted(*args: object, **kwargs: object):  # type: ignore[no-untyped-def]
        fit = real(*args, **kwargs)
        return replace(fit, X=fit.X @ homogeneous(np.eye(3), [0.03, 0.0, 0.0]))

    monkeypatch.setattr(solvers, "solve_likelihood", shifted)
    words = next(w for w in calibrate(Hn, Cn, "ml").warnings if w.startswith("ml is "))
    assert words.startswith("ml is 30") and "tsai, park_martin, kronecker, dual_quaternion" in words
