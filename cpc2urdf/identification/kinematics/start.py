"""Where an identification starts: the closed form, or the nominal model placed in world.

The maximum-likelihood refinement (:mod:`refine`) and the consistency gate's refits of the data's
likely mistakes (:mod:`consistency`) both need a model close to the robot before they can
minimise eq. (23). One-joint-at-a-time data give it in closed form (sec. 4.2,
:mod:`closed_form`); other data start from the robot's nominal model, first placed in the
measuring system's world by a rigid fit of the measured frame origins (:func:`align_base`).
"""

from __future__ import annotations

import numpy as np

from cpc2urdf.errors import DegenerateDataError
from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.model import CPCModel, CPCParams
from cpc2urdf.registration import transforms_from_point_pairs


def closed_form_model(ms: MeasurementSet, nominal: CPCModel | None) -> CPCModel:
    """Shih et al. sec. 4.2 generalised to trees, with its ``provenance`` and ``notes``.

    Raises:
        DegenerateDataError: The records do not follow the one-joint-at-a-time protocol, or do
            not determine the robot (the message says why).
    """
    from cpc2urdf.identification.kinematics.closed_form import identify_closed_form, provenance
    from cpc2urdf.identification.kinematics.protocol import recognise_protocol

    protocol = recognise_protocol(ms)
    model, details = identify_closed_form(ms, nominal, protocol=protocol)
    meta = model.metadata.replace(
        provenance=provenance(ms, protocol, details), notes=tuple(details.notes)
    )
    return model.with_params(metadata=meta)


def measured_frames(model: CPCModel, ms: MeasurementSet) -> list[str]:
    """Frames of ``model`` with at least one measured pose in ``ms``, in the model's order."""
    return [f for f in model.structure.frame_names if f in ms.poses and bool(ms.has_pose(f).any())]


def align_base(model: CPCModel, ms: MeasurementSet, frames: list[str]) -> CPCModel:
    """``model`` with ``T_world_base`` re-fitted so its frame origins best match the measured ones.

    A nominal model usually does not know where the robot stands in the measuring system's
    world; the chart of :class:`Parametrization` keeps ``T_world_base`` fixed (gauge), so a start
    must be placed first. Rigid fit of all measured origins (sec. 3.3's registration, Arun
    eqs. (18)-(22), :func:`~cpc2urdf.registration.transforms_from_point_pairs`).

    Args:
        model: The model to place (typically the nominal one).
        ms: Measurements with ``T_world_<frame>`` poses.
        frames: Frames whose measured origins take part, each measured at least once.
    """
    T_pred = model.fk(ms.q, frames)
    a, b = [], []
    for f in frames:
        ok = ms.has_pose(f)
        a.append(T_pred[f][ok, :3, 3])
        b.append(ms.poses[f][ok, :3, 3])
    G = transforms_from_point_pairs(
        np.concatenate(a), np.concatenate(b), what="measured frame origins"
    )
    return model.with_params(world_to_base=CPCParams.from_matrix(G @ model.T_world_base()))


def on_the_parts(model: CPCModel, nominal: CPCModel | None) -> CPCModel:
    """``model`` with what the data cannot see chosen closest to ``nominal`` (:mod:`gauge`), so every
    link frame sits on its part; measured frames unchanged. The refinement keeps that choice (its
    chart fixes the gauge). Applied to the model a method returns, not to the consistency gate's
    refits, whose gauge does not matter."""
    if nominal is None or nominal.structure.joint_names != model.structure.joint_names:
        return model
    from cpc2urdf.identification.kinematics.gauge import align_to_nominal

    return align_to_nominal(model, nominal)


def refinement_start(
    ms: MeasurementSet, nominal: CPCModel | None
) -> tuple[CPCModel, str, str | None]:
    """The model a refinement of ``ms`` starts from.

    Returns:
        ``(start, kind, note)``: the closed form (``kind = "closed-form"``, ``note`` None), or,
        when the records do not follow the protocol, the nominal model placed in world
        (``"nominal"``, with a note saying why).

    Raises:
        DegenerateDataError: Neither the closed form nor a nominal model can start it.
    """
    try:
        return closed_form_model(ms, nominal), "closed-form", None
    except DegenerateDataError as e:
        if nominal is None:
            raise DegenerateDataError(
                f"refined identification needs a start: the closed form failed ({e}) and the robot "
                "has no nominal geometry"
            ) from e
        note = (
            f"closed form not applicable ({e}); refinement started from the nominal model placed "
            "in world by a rigid fit of the measured plate origins"
        )
        return align_base(nominal, ms, measured_frames(nominal, ms)), "nominal", note


__all__ = ["align_base", "closed_form_model", "measured_frames", "on_the_parts", "refinement_start"]
