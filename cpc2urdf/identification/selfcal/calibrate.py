"""A head calibrated by its own cameras: start, pixel fit, consistency gate, the model it gives.

:func:`calibrate_head` runs the one-stage calibration of :class:`PixelData`:

- **start**: a fixed board's PnP poses through the pose pipeline (:mod:`start`: the closed form
  for one-joint-at-a-time records, else the user's model placed in the board's world), or, for a
  board the robot holds, the user's model with the board's placement from PnP;
- **fit** on pixels (:func:`~cpc2urdf.identification.selfcal.bundle.fit_pixels`);
- **gate**: the corners must fit to a detector's precision (:data:`MAX_CORNER_NOISE`), and the fit
  must not move a joint or camera implausibly far from the user's model (:data:`MAX_SHIFT`,
  :data:`MAX_TURN`). The cause is named by refitting the likely mistakes in turn, the first
  whose fit passes: intrinsics that do not fit the images (refit with them free), a board whose
  file has the wrong square size (refit with its scale free).

The model carries ``provenance`` (the corners, the noise, the start, the parameters the images
do not determine), ``uncertainty`` (the pixel model's covariance) and ``notes`` (outliers).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cpc2urdf.errors import InconsistentDataError
from cpc2urdf.identification.kinematics.start import on_the_parts
from cpc2urdf.identification.selfcal.bundle import PixelFit, fit_pixels
from cpc2urdf.identification.selfcal.pixel_problem import PixelData
from cpc2urdf.identification.selfcal.start import held_board_start, two_stage_fit
from cpc2urdf.model import CPCModel
from cpc2urdf.model_metadata import Covariance, Provenance
from cpc2urdf.transforms import rotation_error

METHOD = "pixels"
MAX_CORNER_NOISE = 2.0  # [px]: corners fitting worse than this are not a detector's noise
MAX_SHIFT = 0.03  # [m]: a joint or camera placement moved farther from the user's is implausible
MAX_TURN = np.radians(10.0)  # [rad]


@dataclass
class HeadCalibration:
    """What :func:`calibrate_head` gives.

    Attributes:
        model: The calibrated model (camera frames optical; world = the board when fixed).
        fit: The pixel fit.
        two_stage: The pose pipeline's model on the same images (fixed board), or None.
        start: ``"closed-form"``, ``"nominal"`` (the user's model) or ``"nominal, board from PnP"``.
    """

    model: CPCModel
    fit: PixelFit
    two_stage: CPCModel | None
    start: str


def _moved(fitted: CPCModel, start: CPCModel) -> tuple[str, float, float]:
    """The placement (joint or frame) that moved most from ``start``, what the images cannot see
    chosen closest to it first (:func:`on_the_parts`): name, shift [m], turn [rad]."""
    fitted = on_the_parts(fitted, start)
    worst = ("", 0.0, 0.0)
    for kind, a, b in (
        ("joint", fitted.joints, start.joints),
        ("frame", fitted.frames, start.frames),
    ):
        for n in a:
            A, B = a[n].matrix(), b[n].matrix()
            shift = float(np.linalg.norm(A[:3, 3] - B[:3, 3]))
            turn = float(rotation_error(A[:3, :3], B[:3, :3]))
            if shift / MAX_SHIFT + turn / MAX_TURN > worst[1] / MAX_SHIFT + worst[2] / MAX_TURN:
                worst = (f"{kind} {n}", shift, turn)
    return worst


def _inconsistency(fit: PixelFit, user: CPCModel) -> str | None:
    """Why ``fit`` does not look like the user's robot seen by a detector, or None."""
    c, s = max(fit.sigma.items(), key=lambda kv: kv[1])
    if s > MAX_CORNER_NOISE:
        return f"camera {c}'s corners fit to {s:.3g} px RMS, more than a detector's {MAX_CORNER_NOISE:g} px"
    name, shift, turn = _moved(fit.model, user)
    if shift > MAX_SHIFT or turn > MAX_TURN:
        return (
            f"the fit moves {name} {shift * 1e3:.1f} mm / {np.degrees(turn):.1f} deg from the user's "
            f"model (plausible: {MAX_SHIFT * 1e3:g} mm / {np.degrees(MAX_TURN):g} deg)"
        )
    return None


def _intrinsics_say(fit: PixelFit) -> str:
    fx = ", ".join(
        f"{c} fx = {m.K[0, 0]:.1f}, fy = {m.K[1, 1]:.1f} px" for c, m in fit.cameras.items()
    )
    return f"the intrinsics do not fit the images (refined: {fx}); recalibrate the cameras or refine them (--intrinsics)"


def _board_says(fit: PixelFit) -> str:
    return f"the board is {fit.board_scale:.4g} times the size its file says; fix the square size in the board file"


def _gate(
    fit: PixelFit, begin: CPCModel, user: CPCModel, data: PixelData, intrinsics: bool
) -> str | None:
    """Why the fit is inconsistent with the images (module docstring), or None. The cause is the
    first likely mistake whose refit is consistent: intrinsics, then the board's size."""
    why = _inconsistency(fit, user)
    if why is None:
        return None
    for refine_intrinsics, scale, says in (
        (True, False, _intrinsics_say),
        (intrinsics, True, _board_says),
    ):
        if refine_intrinsics == intrinsics and not scale:
            continue  # the intrinsics were refined already
        other = fit_pixels(begin, data, intrinsics=refine_intrinsics, board_scale=scale)
        if _inconsistency(other, user) is None:
            return f"{why}: {says(other)}"
    return (
        f"{why}; neither the intrinsics nor the board's size explain it: the joint readings (a "
        "sign, a zero), the camera links or the board's mounting do not match the images"
    )


def _covariance(fit: PixelFit) -> Covariance:
    P = fit.chart.n_params
    return Covariance(
        tuple(fit.chart.names),
        tuple(fit.chart.units),
        tuple(fit.chart.frames),
        fit.chart_covariance(),
        fit.null_space[:P],
        "a_posteriori",
        1.0,
        max(2 * fit.corners - fit.covariance.shape[0] + fit.null_space.shape[1], 1),
        0.0,
        0.0,
        details={"pixel_noise_px": fit.sigma, "model": "board corners in pixels"},
    )


def calibrate_head(
    nominal: CPCModel,
    data: PixelData,
    *,
    intrinsics: bool = False,
    accept_inconsistent: bool = False,
) -> HeadCalibration:
    """One-stage calibration of ``data`` about the user's ``nominal`` model (module docstring).

    Args:
        nominal: The user's model, with every camera frame of ``data`` (optical) and, for a held
            board, the board's frame on its link.
        data: The images' corners.
        intrinsics: Refine each camera's ``fx, fy, cx, cy, k1, k2`` too.
        accept_inconsistent: Keep a model the gate refuses, the reason in its notes.

    Raises:
        InconsistentDataError: The gate's reason (unless ``accept_inconsistent``).
    """
    two: CPCModel | None = None
    if data.board_frame is None:
        res, kind = two_stage_fit(data, nominal)
        two, user, begin = res.model, res.start, res.model
    else:
        kind = "nominal, board from PnP"
        user = begin = held_board_start(data, nominal)
    fit = fit_pixels(begin, data, intrinsics=intrinsics)
    notes = [f"outlier: {o}" for o in fit.outliers]
    if fit.undetermined:
        notes.append(
            "not determined by the images, kept at the user's values: "
            + ", ".join(fit.undetermined)
        )
    # A closed-form start is the images' own: only the noise is checked then.
    reason = _gate(fit, begin, fit.model if kind == "closed-form" else user, data, intrinsics)
    if reason is not None:
        if not accept_inconsistent:
            raise InconsistentDataError(f"{data.source}: {reason}")
        notes.append(f"inconsistent (kept on request): {reason}")
    prov = Provenance(
        method=METHOD,
        measurements=data.source,
        details={
            "reference": "maximum likelihood on the board's corners in pixels (bundle adjustment "
            "of the joints, camera mounts and board), started from " + kind,
            "start": kind,
            "images": len(fit.view_rms),
            "corners": fit.corners,
            "pixel_noise_px": fit.sigma,
            "intrinsics_refined": intrinsics,
            "cameras": {
                c: {"K": cam.K.tolist(), "D": cam.D.tolist()} for c, cam in fit.cameras.items()
            },
            "board_frame": data.board_frame,
            "undetermined": fit.undetermined,
            "outliers": fit.outliers,
            "seconds": fit.seconds,
        },
    )
    meta = fit.model.metadata.replace(
        provenance=prov, uncertainty=_covariance(fit), notes=tuple(notes)
    )
    return HeadCalibration(fit.model.with_params(metadata=meta), fit, two, kind)


__all__ = [
    "MAX_CORNER_NOISE",
    "MAX_SHIFT",
    "MAX_TURN",
    "METHOD",
    "HeadCalibration",
    "calibrate_head",
]
