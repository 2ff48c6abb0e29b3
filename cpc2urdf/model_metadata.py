"""What an identified model carries besides its geometry, as types: where it came from, how well
it fits its data, how far to trust it, and how its cameras were calibrated.

These are the optional sections of a ``cpc2urdf/model@1`` file (:mod:`cpc2urdf.files.model_file`)::

    "description": "...",
    "provenance":  {"method": "refined", "measurements": "...", "robot": "...", ...},
    "residuals":   {"per_frame": {frame: {...}}, "per_record": [{"label": ..., frame: {...}}]},
    "uncertainty": {"format": "cpc2urdf/uncertainty@1", "parameters": [...], "covariance": ...},
    "handeye":     {camera: {"hand": ..., "method": ..., "T_hand_camera": ..., ...}, "units": ...},
    "notes":       ["...", ...]

Each section is one frozen dataclass with ``to_json``/``from_json``; the file format is unchanged.
Units: SI inside (m, rad), except the hand-eye residuals, which the file has always given in mm and
degrees (their field names say so).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import Cpc2UrdfError

Array = NDArray[np.float64]

UNCERTAINTY_FORMAT = "cpc2urdf/uncertainty@1"
HANDEYE_UNITS_NOTE = {"note": "T_* matrices in metres; residuals in mm and deg"}


class NoUncertaintyError(Cpc2UrdfError):
    """The model carries no (or an unusable) ``uncertainty`` section."""


# ---- provenance ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Provenance:
    """Where a model came from.

    Attributes:
        method: How it was made (an identification method name, ``"simulated truth"``, ...).
        measurements: The measurement file it was identified from, if any.
        robot: The robot reference those measurements named, if any.
        details: Method-specific facts (protocol summary, parameter counts, the start of a
            refinement, timing, ...), JSON-compatible, kept in the file as they are.
    """

    method: str | None = None
    measurements: str | None = None
    robot: str | None = None
    details: Mapping[str, Any] = field(default_factory=dict)

    _KEYS = ("method", "measurements", "robot")

    def with_details(self, **details: Any) -> Provenance:
        """A copy with ``details`` added (replacing keys of the same name)."""
        return replace(self, details={**self.details, **details})

    def to_json(self) -> dict[str, Any]:
        out = {k: getattr(self, k) for k in self._KEYS if getattr(self, k) is not None}
        return {**out, **{k: v for k, v in self.details.items() if k not in self._KEYS}}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Provenance:
        if not isinstance(d, Mapping):
            raise ValueError(f"'provenance' must be an object, got {type(d).__name__}")
        known = {k: (None if d.get(k) is None else str(d[k])) for k in cls._KEYS}
        return cls(**known, details={k: v for k, v in d.items() if k not in cls._KEYS})


# ---- fit residuals ------------------------------------------------------------------------------


@dataclass(frozen=True)
class FrameResiduals:
    """Fit residuals of one measured frame over the records that measured it.

    Attributes:
        records: How many records measured the frame.
        rms_translation_m: RMS distance between measured and predicted origins [m].
        max_translation_m: Largest such distance [m].
        rms_rotation_rad: RMS angle between measured and predicted orientations [rad].
        max_rotation_rad: Largest such angle [rad].
    """

    records: int
    rms_translation_m: float
    max_translation_m: float
    rms_rotation_rad: float
    max_rotation_rad: float

    def to_json(self) -> dict[str, Any]:
        return {
            "records": self.records,
            "rms_translation_m": self.rms_translation_m,
            "max_translation_m": self.max_translation_m,
            "rms_rotation_rad": self.rms_rotation_rad,
            "max_rotation_rad": self.max_rotation_rad,
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> FrameResiduals:
        return cls(
            int(d["records"]),
            float(d["rms_translation_m"]),
            float(d["max_translation_m"]),
            float(d["rms_rotation_rad"]),
            float(d["max_rotation_rad"]),
        )


@dataclass(frozen=True)
class RecordResiduals:
    """Residuals of one record: frame -> (translation [m], rotation [rad])."""

    label: str
    per_frame: Mapping[str, tuple[float, float]]

    def to_json(self) -> dict[str, Any]:
        return {
            "label": self.label,
            **{f: {"translation_m": t, "rotation_rad": r} for f, (t, r) in self.per_frame.items()},
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> RecordResiduals:
        return cls(
            str(d["label"]),
            {
                f: (float(v["translation_m"]), float(v["rotation_rad"]))
                for f, v in d.items()
                if f != "label"
            },
        )


@dataclass(frozen=True)
class Residuals:
    """How well a model fits the measurements it was identified from."""

    per_frame: Mapping[str, FrameResiduals]
    per_record: tuple[RecordResiduals, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {
            "per_frame": {f: r.to_json() for f, r in self.per_frame.items()},
            "per_record": [r.to_json() for r in self.per_record],
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Residuals:
        return cls(
            {str(f): FrameResiduals.from_json(v) for f, v in d["per_frame"].items()},
            tuple(RecordResiduals.from_json(r) for r in d.get("per_record", [])),
        )


# ---- uncertainty --------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Covariance:
    """Covariance of a model's identifiable parameters in its own local chart
    (:mod:`cpc2urdf.identification.kinematics.uncertainty` computes and propagates it).

    Attributes:
        names: Parameter names, length P (``"<owner>.<param>"``).
        units: ``"m"`` or ``"rad"`` per parameter.
        frames: Measured frames the parametrisation was built for.
        matrix: Covariance [m^2, m rad, rad^2], shape (P, P); zero along undetermined directions.
        null_space: Undetermined directions, shape (P, k) (k = 0 when fully identifiable).
        scale: ``"known"`` (the noise sigmas are trusted) or ``"a_posteriori"`` (scaled by the
            residuals' variance factor).
        variance_factor: ``s0^2 = |r|^2 / dof`` of the weighted residuals (1 when the sigmas
            are right), whatever the scale.
        dof: Residuals minus rank.
        sigma_t: Translation noise [m] the weights assumed.
        sigma_r: Rotation-angle noise [rad] the weights assumed.
        details: What the estimator reported with it (the refinement's settings, identifiability,
            outliers), JSON-compatible, kept in the file as it is.
    """

    names: tuple[str, ...]
    units: tuple[str, ...]
    frames: tuple[str, ...]
    matrix: Array
    null_space: Array
    scale: str
    variance_factor: float
    dof: int
    sigma_t: float
    sigma_r: float
    details: Mapping[str, Any] = field(default_factory=dict)

    _KEYS = (
        "format",
        "units",
        "method",
        "chart",
        "scale",
        "variance_factor",
        "dof",
        "sigma_t",
        "sigma_r",
        "frames",
        "parameters",
        "parameter_units",
        "std",
        "covariance",
        "null_space",
    )

    @property
    def std(self) -> Array:
        """Standard deviation per parameter [m] or [rad]; NaN where undetermined."""
        sd = np.sqrt(np.clip(np.diag(self.matrix), 0.0, None))
        if self.null_space.size:
            touched = np.linalg.norm(self.null_space, axis=1) > 1e-9
            sd = np.where(touched, np.nan, sd)
        return sd

    def to_json(self) -> dict[str, Any]:
        """The model-file section (SI units; NaN std as null)."""
        return {
            "format": UNCERTAINTY_FORMAT,
            "units": {"length": "m", "angle": "rad"},
            "method": "first-order covariance of the weighted least-squares estimate",
            "chart": "local CPC update of this model's own parameters (identification/kinematics/parametrization.py)",
            "scale": self.scale,
            "variance_factor": self.variance_factor,
            "dof": self.dof,
            "sigma_t": self.sigma_t,
            "sigma_r": self.sigma_r,
            "frames": list(self.frames),
            "parameters": list(self.names),
            "parameter_units": list(self.units),
            "std": [None if not np.isfinite(v) else float(v) for v in self.std],
            "covariance": [[float(v) for v in row] for row in self.matrix],
            "null_space": [[float(v) for v in row] for row in self.null_space],
            **{k: v for k, v in self.details.items() if k not in self._KEYS},
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any], source: str = "<model>") -> Covariance:
        """Parse a model file's ``uncertainty`` section (errors name ``source``)."""
        try:
            if d.get("format") != UNCERTAINTY_FORMAT:
                raise ValueError(f"format is {d.get('format')!r}, expected {UNCERTAINTY_FORMAT!r}")
            names = tuple(str(n) for n in d["parameters"])
            P = len(names)
            C = np.asarray(d["covariance"], dtype=float).reshape(P, P)
            ns = d.get("null_space") or []
            N0 = np.asarray(ns, dtype=float).reshape(P, -1) if len(ns) else np.zeros((P, 0))
            if not np.all(np.isfinite(C)):
                raise ValueError("covariance has non-finite entries")
            return cls(
                names,
                tuple(str(u) for u in d["parameter_units"]),
                tuple(str(f) for f in d["frames"]),
                C,
                N0,
                str(d["scale"]),
                float(d["variance_factor"]),
                int(d["dof"]),
                float(d["sigma_t"]),
                float(d["sigma_r"]),
                {k: v for k, v in d.items() if k not in cls._KEYS},
            )
        except (KeyError, TypeError, ValueError, AttributeError) as e:
            raise NoUncertaintyError(f"{source}: bad 'uncertainty' section: {e}") from e


# ---- hand-eye -----------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class HandEyeRecord:
    """How one camera frame was calibrated (stage 2: ``A X = Z B``).

    Attributes:
        hand: Frame of the model the camera is fixed to.
        method: Hand-eye solver name.
        T_hand_camera: ``X`` [m], shape (4, 4).
        T_base_target: ``Z`` [m], shape (4, 4).
        residual_translation_mm: Per-pose position residual [mm], shape (n_poses,).
        residual_rotation_deg: Per-pose angle residual [deg], shape (n_poses,).
        warnings: The solver's warnings.
        details: Anything else the producer recorded (e.g. the pose file), JSON-compatible.
    """

    hand: str
    method: str
    T_hand_camera: Array
    T_base_target: Array
    residual_translation_mm: Array
    residual_rotation_deg: Array
    warnings: tuple[str, ...] = ()
    details: Mapping[str, Any] = field(default_factory=dict)

    @property
    def n_poses(self) -> int:
        return int(len(self.residual_translation_mm))

    @property
    def rms_translation_mm(self) -> float:
        return float(np.sqrt(np.mean(np.square(self.residual_translation_mm))))

    @property
    def rms_rotation_deg(self) -> float:
        return float(np.sqrt(np.mean(np.square(self.residual_rotation_deg))))

    _KEYS = (
        "hand",
        "method",
        "n_poses",
        "T_hand_camera",
        "T_base_target",
        "rms_translation_mm",
        "rms_rotation_deg",
        "residual_translation_mm",
        "residual_rotation_deg",
        "warnings",
    )

    def to_json(self) -> dict[str, Any]:
        return {
            "hand": self.hand,
            "method": self.method,
            "n_poses": self.n_poses,
            **{k: v for k, v in self.details.items() if k not in self._KEYS},
            "T_hand_camera": np.asarray(self.T_hand_camera).tolist(),
            "T_base_target": np.asarray(self.T_base_target).tolist(),
            "rms_translation_mm": self.rms_translation_mm,
            "rms_rotation_deg": self.rms_rotation_deg,
            "residual_translation_mm": np.asarray(self.residual_translation_mm).tolist(),
            "residual_rotation_deg": np.asarray(self.residual_rotation_deg).tolist(),
            "warnings": list(self.warnings),
        }

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> HandEyeRecord:
        return cls(
            str(d["hand"]),
            str(d["method"]),
            np.asarray(d["T_hand_camera"], dtype=float).reshape(4, 4),
            np.asarray(d["T_base_target"], dtype=float).reshape(4, 4),
            np.asarray(d.get("residual_translation_mm", []), dtype=float),
            np.asarray(d.get("residual_rotation_deg", []), dtype=float),
            tuple(str(w) for w in d.get("warnings", [])),
            {k: v for k, v in d.items() if k not in cls._KEYS},
        )


# ---- all of it ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class ModelMetadata:
    """Everything a model carries besides its geometry (every field optional)."""

    description: str | None = None
    provenance: Provenance | None = None
    residuals: Residuals | None = None
    uncertainty: Covariance | None = None
    handeye: Mapping[str, HandEyeRecord] = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    def replace(self, **changes: Any) -> ModelMetadata:
        """A copy with some sections replaced (``dataclasses.replace``)."""
        return replace(self, **changes)

    def with_notes(self, notes: Sequence[str]) -> ModelMetadata:
        """A copy with ``notes`` appended."""
        return replace(self, notes=(*self.notes, *notes))

    def to_json(self) -> dict[str, Any]:
        """The optional sections of a model file (only those present)."""
        out: dict[str, Any] = {}
        if self.description is not None:
            out["description"] = self.description
        if self.provenance is not None:
            out["provenance"] = self.provenance.to_json()
        if self.uncertainty is not None:
            out["uncertainty"] = self.uncertainty.to_json()
        if self.residuals is not None:
            out["residuals"] = self.residuals.to_json()
        if self.handeye:
            out["handeye"] = {c: r.to_json() for c, r in self.handeye.items()}
            out["handeye"]["units"] = dict(HANDEYE_UNITS_NOTE)
        if self.notes:
            out["notes"] = list(self.notes)
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any], source: str = "<model>") -> ModelMetadata:
        """Parse the optional sections of a model file document ``d``.

        Raises:
            ValueError: Naming the section and what is wrong with it.
        """

        def section(name: str, parse: Any) -> Any:
            if name not in d:
                return None
            try:
                return parse(d[name])
            except (KeyError, TypeError, ValueError, AttributeError) as e:
                raise ValueError(f"bad {name!r} section: {e}") from e

        notes = section("notes", lambda v: tuple(str(n) for n in v)) or ()
        if "notes" in d and isinstance(d["notes"], str):
            raise ValueError("bad 'notes' section: expected a list of strings")
        handeye = (
            section(
                "handeye",
                lambda v: {
                    str(c): HandEyeRecord.from_json(r) for c, r in v.items() if c != "units"
                },
            )
            or {}
        )
        description = section("description", str)
        uncertainty = None
        if "uncertainty" in d:
            try:
                uncertainty = Covariance.from_json(d["uncertainty"], source)
            except NoUncertaintyError as e:
                raise ValueError(str(e).removeprefix(f"{source}: ")) from e
        return cls(
            description=description,
            provenance=section("provenance", Provenance.from_json),
            residuals=section("residuals", Residuals.from_json),
            uncertainty=uncertainty,
            handeye=handeye,
            notes=notes,
        )


__all__ = [
    "HANDEYE_UNITS_NOTE",
    "UNCERTAINTY_FORMAT",
    "Covariance",
    "FrameResiduals",
    "HandEyeRecord",
    "ModelMetadata",
    "NoUncertaintyError",
    "Provenance",
    "RecordResiduals",
    "Residuals",
]
