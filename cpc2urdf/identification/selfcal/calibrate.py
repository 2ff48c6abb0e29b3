"""A head calibrated by its own cameras: start, pixel fit, consistency gate, the model it gives.

:func:`calibrate_head` runs the one-stage calibration of :class:`PixelData`:

- **start**: a fixed board's PnP poses through the pose pipeline (:mod:`start`: the closed form
  for one-joint-at-a-time records, else the user's model placed in the board's world), or, for a
  board the robot holds, the user's model with the board's placement from PnP;
- **fit** on pixels (:func:`~cpc2urdf.identification.selfcal.bundle.fit_pixels`);
- **gate**: the likely mistakes are refitted first, since a few % off still fits, only worse:
  intrinsics that do not fit the images (refitted free, the corners fit
  :data:`INTRINSICS_GAIN` times closer), a board whose file has the wrong square size (its scale
  refitted free and settled by the user's lengths, off by more than :data:`MAX_BOARD_SCALE`).
  Then the corners must fit to a detector's precision (:data:`MAX_CORNER_NOISE`), no joint axis
  may turn the other way, and no joint or camera may move implausibly far from the user's model
  (:data:`MAX_SHIFT`, :data:`MAX_TURN`).

The model carries ``provenance`` (the corners, the noise, the start, the parameters the images
do not determine), ``uncertainty`` (the pixel model's covariance) and ``notes`` (outliers).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cpc2urdf.errors import DegenerateDataError, InconsistentDataError
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
INTRINSICS_GAIN = 1.3  # refined intrinsics fitting the corners this much closer: they were off
MAX_BOARD_SCALE = 0.02  # [-] a board this much off its file's size (the URDF's lengths say)


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


def _moved(fitted: CPCModel, start: CPCModel) -> tuple[str, float, float, list[str]]:
    """The placement (joint or frame) that moved most from ``start``, what the images cannot see
    chosen closest to it first (:func:`on_the_parts`): name, shift [m], turn [rad]; and the
    joints whose axis the fit reverses."""
    try:
        fitted = on_the_parts(fitted, start)
    except DegenerateDataError:  # no gauge brings it near the user's model
        return "the robot", float("inf"), float("inf"), []
    worst = ("", 0.0, 0.0)
    reversed_ = [
        n
        for n in fitted.joints
        if fitted.joints[n].matrix()[:3, 2] @ start.joints[n].matrix()[:3, 2] < 0
    ]
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
    return (*worst, reversed_)


def _inconsistency(fit: PixelFit, user: CPCModel, data: PixelData) -> str | None:
    """Why ``fit`` does not look like the user's robot seen by a detector, or None."""
    c, s = max(fit.sigma.items(), key=lambda kv: kv[1])
    if s > MAX_CORNER_NOISE:
        return (
            f"camera {data.name(c)}'s corners fit to {s:.3g} px RMS, more than a detector's "
            f"{MAX_CORNER_NOISE:g} px"
        )
    name, shift, turn, flipped = _moved(fit.model, user)
    if flipped:
        return (
            f"joint {flipped[0]} turns the other way than in the URDF (the images reverse its "
            "axis): a sign in the joint readings or in the URDF's <axis>"
        )
    if shift > MAX_SHIFT or turn > MAX_TURN:
        return (
            f"the fit moves {data.name(name)} {shift * 1e3:.1f} mm / {np.degrees(turn):.1f} deg "
            f"from the user's model (plausible: {MAX_SHIFT * 1e3:g} mm / {np.degrees(MAX_TURN):g} deg)"
        )
    return None


def _gate(
    fit: PixelFit, begin: CPCModel, user: CPCModel, data: PixelData, intrinsics: bool
) -> str | None:
    """Why the fit is inconsistent with the images (module docstring), or None. The likely
    mistakes are refitted whatever the first fit says (a few % off still fits, worse), and named
    when their refit is consistent: intrinsics that do not fit the images, then a board whose
    file has the wrong size (its scale settled by the user's lengths); then the corners' noise
    and how far the fit moved."""
    if not intrinsics:
        other = fit_pixels(begin, data, intrinsics=True)
        gain = max(fit.sigma[c] / other.sigma[c] for c in fit.sigma)
        if gain > INTRINSICS_GAIN and _inconsistency(other, user, data) is None:
            fx = ", ".join(
                f"{data.name(c)} fx = {m.K[0, 0]:.1f}, fy = {m.K[1, 1]:.1f} px"
                for c, m in other.cameras.items()
            )
            return (
                f"the intrinsics do not fit the images: refined ({fx}) the corners fit "
                f"{gain:.3g} times closer; recalibrate the cameras or refine them (--intrinsics)"
            )
    scaled = fit_pixels(user, data, intrinsics=intrinsics, board_scale=True)
    if (
        abs(scaled.board_scale - 1.0) > MAX_BOARD_SCALE
        and _inconsistency(scaled, user, data) is None
    ):
        return (
            f"the board is about {scaled.board_scale:.3g} times the size its file says (the "
            "URDF's lengths against the images'); fix the square size in the board file"
        )
    why = _inconsistency(fit, user, data)
    if why is None or "turns the other way" in why:
        return why
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
        res, kind, user = two_stage_fit(data, nominal)
        two, begin = res.model, res.model
    else:
        kind = "nominal, board from PnP"
        user = begin = held_board_start(data, nominal)
    fit = fit_pixels(begin, data, intrinsics=intrinsics)
    notes = [f"skipped: {p}" for p in data.notes] + [f"outlier: {o}" for o in fit.outliers]
    if fit.undetermined:
        notes.append(
            "not determined by the images (chosen closest to the user's model): "
            + data.name(", ".join(fit.undetermined))
        )
    reason = _gate(fit, begin, user, data, intrinsics)
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
    "INTRINSICS_GAIN",
    "MAX_BOARD_SCALE",
    "MAX_CORNER_NOISE",
    "MAX_SHIFT",
    "MAX_TURN",
    "METHOD",
    "HeadCalibration",
    "calibrate_head",
]
