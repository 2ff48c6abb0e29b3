"""What ``cpc2urdf export`` writes for a robot reference: the model and its physical properties.

The geometry is the reference's model (a model file, or a spec's nominal model). Density, masses
and the up direction (:class:`~cpc2urdf.urdf.physical.PhysicalProperties`) are a robot's, not a
calibration's, so they come from the robot spec: the reference itself when it is a spec or a
shipped robot, else the robot a model file's provenance names (``provenance.robot``, tried
against the model file's folder first). ``--up`` overrides the up direction. What cannot be found
falls back to the defaults (1000 kg/m^3, base +z up), and :attr:`ExportPlan.physical_from` says so.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from cpc2urdf.errors import ConfigurationError, Cpc2UrdfError
from cpc2urdf.files.robot_ref import RobotRef, load_robot
from cpc2urdf.files.spec import RobotSpec
from cpc2urdf.model import CPCModel
from cpc2urdf.urdf.document import urdf_link_names
from cpc2urdf.urdf.physical import PhysicalProperties


@dataclass(frozen=True)
class ExportPlan:
    """The model to export and the physical properties its URDF gets.

    Attributes:
        model: The model (geometry, tree).
        physical: Density, masses (only those naming links of this model's URDF), up.
        physical_from: Where they came from, for the user (``"spec iis_head"``, ``"defaults ..."``).
    """

    model: CPCModel
    physical: PhysicalProperties
    physical_from: str


def _robot_of_model(spec: RobotSpec) -> tuple[RobotSpec | None, str]:
    """The robot spec a model's provenance names, if it states physical properties; else None
    and why not."""
    prov = spec.nominal_model().metadata.provenance
    ref = prov.robot if prov is not None else None
    if not ref:
        return None, "defaults (none stated)"
    folder = Path(spec.source).parent if not spec.source.startswith("<") else None
    try:
        robot = load_robot(ref, relative_to=folder)
    except Cpc2UrdfError as e:
        return None, f"defaults (the model's robot {ref!r} cannot be read: {e})"
    if not robot.physical.stated:
        return None, f"defaults (the model's robot {ref!r} states none)"
    return robot, f"robot {ref}"


def plan_export(ref: RobotRef | CPCModel, *, up: ArrayLike | None = None) -> ExportPlan:
    """The model of ``ref`` and the physical properties its URDF gets (see the module docstring).

    Args:
        ref: A model, a model file, a robot spec or a shipped robot name.
        up: An up direction in base coordinates (shape (3,)) overriding the spec's.

    Raises:
        InputFileError: ``ref`` cannot be read (:func:`~cpc2urdf.files.robot_ref.load_robot`).
        SpecError: A spec without nominal geometry.
        ConfigurationError: ``up`` is zero or not finite.
    """
    if isinstance(ref, CPCModel):
        spec: RobotSpec = RobotSpec(ref.structure, ref, f"<model {ref.structure.name}>")
    else:
        spec = load_robot(ref)
    model = spec.nominal_model()
    source: RobotSpec | None = spec
    where = f"spec {spec.source}"
    if not spec.physical.stated:  # a model file (or a spec stating nothing): ask its robot
        source, where = _robot_of_model(spec)
    physical = source.physical if source is not None else PhysicalProperties()
    if physical.up_joint is not None and physical.up_joint not in model.structure.joint_names:
        physical = replace(physical, up_joint=None, up_sign=1.0)
        where += f" (its up joint is not a joint of {model.structure.name!r}: base +z up)"
    links = urdf_link_names(model.structure)
    kept = {k: v for k, v in physical.masses.items() if k in links}
    if len(kept) != len(physical.masses):
        physical = replace(physical, masses=kept)
    if up is not None:
        u = np.asarray(up, dtype=float).reshape(-1)
        n = float(np.linalg.norm(u)) if u.shape == (3,) and np.all(np.isfinite(u)) else 0.0
        if n < 1e-9:
            raise ConfigurationError(
                f"--up must be a non-zero direction X Y Z in base coordinates, got {u.tolist()}"
            )
        v = u / n
        physical = replace(
            physical, up=(float(v[0]), float(v[1]), float(v[2])), up_joint=None, up_sign=1.0
        )
        where += "; up from --up"
    return ExportPlan(model, physical, where)


def describe(plan: ExportPlan, mount: str) -> str:
    """One line about the root and the inertials of an export, for the user."""
    if mount == "rig":
        root = "root 'world' = the measuring rig (--mount rig)"
    else:
        root = f"root 'world' gravity-aligned at the base, up = {plan.physical.describe_up()}"
    return f"{root}; density {plan.physical.density:g} kg/m^3; physical properties from {plan.physical_from}"


__all__ = ["ExportPlan", "describe", "plan_export"]
