"""The likely mistakes in a stage-1 measurement file, each as the fix that undoes it.

When a fit does not match the data's own noise statement (:mod:`consistency`), the gate refits
the data with each fix applied and names the one that makes them consistent. An
:class:`Alternative` is such a fix: a function from the measurements as read to the measurements
as they would be without the mistake, with the words to name it. :func:`alternatives` lists them
for a robot:

- lengths in another unit than the file says (x1000: metres labelled mm, x100, x10 and back),
  for the whole file, and for the poses alone when the robot has prismatic joints (the readings
  scale with the poses when the ``units`` field is wrong, not when only the pose source is);
- revolute readings in radians labelled deg, or the reverse;
- the poses of two measured frames swapped (``plate_left``/``plate_right``);
- the readings of two joints of one type swapped (``vergence_left``/``vergence_right``);
- poses given inverted (``T_plate_world`` instead of ``T_world_plate``);
- rotation blocks transposed (translations right);
- quaternions written w, x, y, z in a ``quat_xyzw`` field (the four numbers are recovered from
  the rotation read and put back in their order);
- readings paired with the next or the previous record's poses (off by one; one record lost).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from cpc2urdf.files.measurements import MeasurementSet
from cpc2urdf.transforms import Array

Fix = Callable[[MeasurementSet], MeasurementSet]

# Length unit factors tried, with the mistake each undoes when the file's lengths are multiplied
# by it (file values read in a unit `factor` times too small/large).
LENGTH_FACTORS: dict[float, str] = {
    1000.0: "metres labelled mm",
    100.0: "metres labelled cm",
    10.0: "centimetres labelled mm",
    0.1: "millimetres labelled cm",
    0.01: "centimetres labelled m",
    0.001: "millimetres labelled m",
}
ANGLE_FACTORS: dict[float, str] = {
    180.0 / math.pi: "radians labelled deg",
    math.pi / 180.0: "degrees labelled rad",
}


@dataclass(frozen=True)
class Alternative:
    """One likely mistake and the fix that undoes it.

    Attributes:
        key: Short identifier, e.g. ``"lengths x1000"``, ``"swap plate_left/plate_right"``.
        kind: ``"lengths"``, ``"pose lengths"``, ``"angles"``, ``"frames"``, ``"joints"``,
            ``"inverted"``, ``"transposed"``, ``"quaternion"`` or ``"pairing"``.
        cause: What the data look like, e.g. ``"lengths look like metres labelled mm"``.
        remedy: What to change in the file, e.g. ``'fix "units"'``.
        apply: The fix, ``MeasurementSet -> MeasurementSet``.
        length_factor: Factor the fix applies to the poses' translations (1 if none): fit
            residuals of fixed data divided by it compare with those of the data as read.
    """

    key: str
    kind: str
    cause: str
    remedy: str
    apply: Fix
    length_factor: float = 1.0


def _rebuild(
    ms: MeasurementSet, q: Array, poses: dict[str, Array], labels: list[str] | None = None
) -> MeasurementSet:
    """A measurement set like ``ms`` with other readings and poses (points and fit RMS dropped)."""
    out = MeasurementSet(
        ms.structure,
        q,
        poses,
        ms.source,
        ms.robot,
        list(labels or ms.labels),
        metadata=dict(ms.metadata),
    )
    out.spec = ms.spec
    return out


def scale_lengths(factor: float, readings: bool = True) -> Fix:
    """Pose translations (and prismatic readings if ``readings``) times ``factor``."""

    def fix(ms: MeasurementSet) -> MeasurementSet:
        q = ms.q.copy()
        if readings:
            prismatic = [k for k, j in enumerate(ms.structure.joints) if j.type == "prismatic"]
            q[:, prismatic] *= factor
        poses = {f: T.copy() for f, T in ms.poses.items()}
        for T in poses.values():
            T[:, :3, 3] *= factor
        return _rebuild(ms, q, poses)

    return fix


def scale_revolute(factor: float) -> Fix:
    """Revolute readings times ``factor``."""

    def fix(ms: MeasurementSet) -> MeasurementSet:
        q = ms.q.copy()
        revolute = [k for k, j in enumerate(ms.structure.joints) if j.type == "revolute"]
        q[:, revolute] *= factor
        return _rebuild(ms, q, {f: T.copy() for f, T in ms.poses.items()})

    return fix


def swap_frames(a: str, b: str) -> Fix:
    """The poses of frames ``a`` and ``b`` exchanged."""

    def fix(ms: MeasurementSet) -> MeasurementSet:
        poses = {f: T.copy() for f, T in ms.poses.items()}
        poses[a], poses[b] = ms.poses[b].copy(), ms.poses[a].copy()
        return _rebuild(ms, ms.q.copy(), poses)

    return fix


def swap_joints(a: int, b: int) -> Fix:
    """The readings of joints ``a`` and ``b`` (column indices) exchanged."""

    def fix(ms: MeasurementSet) -> MeasurementSet:
        q = ms.q.copy()
        q[:, [a, b]] = q[:, [b, a]]
        return _rebuild(ms, q, {f: T.copy() for f, T in ms.poses.items()})

    return fix


def _map_poses(fn: Callable[[Array], Array]) -> Fix:
    def fix(ms: MeasurementSet) -> MeasurementSet:
        poses = {}
        for f, T in ms.poses.items():
            out = np.full_like(T, np.nan)
            ok = ms.has_pose(f)
            if ok.any():
                out[ok] = fn(T[ok])
            poses[f] = out
        return _rebuild(ms, ms.q.copy(), poses)

    return fix


def _invert(T: Array) -> Array:
    Rt = np.swapaxes(T[:, :3, :3], 1, 2)
    out = np.zeros_like(T)
    out[:, :3, :3] = Rt
    out[:, :3, 3] = -np.einsum("nij,nj->ni", Rt, T[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out


def _transpose(T: Array) -> Array:
    out = T.copy()
    out[:, :3, :3] = np.swapaxes(T[:, :3, :3], 1, 2)
    return out


def _quaternion_wxyz(T: Array) -> Array:
    # The file's [w, x, y, z] were read as [x', y', z', w']: recover them from the rotation read
    # (the sign of a quaternion does not matter) and put them back as x, y, z, w.
    read = Rotation.from_matrix(T[:, :3, :3]).as_quat()  # [x', y', z', w'] = [w, x, y, z]
    out = T.copy()
    out[:, :3, :3] = Rotation.from_quat(np.roll(read, -1, axis=1)).as_matrix()
    return out


def shift_pairing(step: int) -> Fix:
    """Readings of record ``i + step`` paired with the poses of record ``i`` (``step`` = +-1).

    ``step = +1`` undoes readings paired with the next record's poses: then the poses in
    record ``i`` belong to the readings of record ``i + 1``.
    """

    def fix(ms: MeasurementSet) -> MeasurementSet:
        n = ms.n_records
        if step > 0:
            q_idx, p_idx = np.arange(step, n), np.arange(0, n - step)
        else:
            q_idx, p_idx = np.arange(0, n + step), np.arange(-step, n)
        poses = {f: T[p_idx].copy() for f, T in ms.poses.items()}
        return _rebuild(ms, ms.q[q_idx].copy(), poses, [ms.labels[int(i)] for i in q_idx])

    return fix


def alternatives(ms: MeasurementSet) -> list[Alternative]:
    """Every fix that applies to the robot and data of ``ms`` (see the module docstring)."""
    s = ms.structure
    out: list[Alternative] = []
    for factor, story in LENGTH_FACTORS.items():
        out.append(
            Alternative(
                f"lengths x{factor:g}",
                "lengths",
                f"lengths look like {story}",
                'fix "units": "length"',
                scale_lengths(factor),
                factor,
            )
        )
    if any(j.type == "prismatic" for j in s.joints):
        for factor in (1000.0, 0.001):
            out.append(
                Alternative(
                    f"pose lengths x{factor:g}",
                    "pose lengths",
                    f"pose lengths look {factor:g}x {'too small' if factor > 1 else 'too large'} for the prismatic "
                    f"readings ({LENGTH_FACTORS[factor]}?)",
                    "convert the poses to the file's length unit",
                    scale_lengths(factor, readings=False),
                    factor,
                )
            )
    if any(j.type == "revolute" for j in s.joints):
        for factor, story in ANGLE_FACTORS.items():
            out.append(
                Alternative(
                    f"revolute readings x{factor:.4g}",
                    "angles",
                    f"revolute readings look like {story}",
                    'fix "units": "angle"',
                    scale_revolute(factor),
                )
            )
    frames = ms.frames
    for a, b in itertools.combinations(frames, 2):
        out.append(
            Alternative(
                f"swap {a}/{b}",
                "frames",
                f"the poses of {a} and {b} look swapped",
                f"swap the {a} and {b} poses",
                swap_frames(a, b),
            )
        )
    for (i, ja), (k, jb) in itertools.combinations(enumerate(s.joints), 2):
        if ja.type == jb.type:
            out.append(
                Alternative(
                    f"swap {ja.name}/{jb.name}",
                    "joints",
                    f"the readings of {ja.name} and {jb.name} look swapped",
                    f"swap the {ja.name} and {jb.name} readings",
                    swap_joints(i, k),
                )
            )
    out += [
        Alternative(
            "inverted poses",
            "inverted",
            "the poses look inverted (T_frame_world given instead of T_world_frame)",
            "invert every pose",
            _map_poses(_invert),
        ),
        Alternative(
            "transposed rotations",
            "transposed",
            "the rotation blocks look transposed",
            "transpose every rotation block",
            _map_poses(_transpose),
        ),
        Alternative(
            "quaternions w,x,y,z",
            "quaternion",
            "the quaternions look written w, x, y, z in 'quat_xyzw'",
            "write them x, y, z, w",
            _map_poses(_quaternion_wxyz),
        ),
    ]
    if ms.n_records > 2:
        out += [
            Alternative(
                "pairing +1",
                "pairing",
                "each record's readings look paired with the next record's poses",
                "pair each record's readings with its own poses",
                shift_pairing(+1),
            ),
            Alternative(
                "pairing -1",
                "pairing",
                "each record's readings look paired with the previous record's poses",
                "pair each record's readings with its own poses",
                shift_pairing(-1),
            ),
        ]
    return out


__all__ = [
    "ANGLE_FACTORS",
    "LENGTH_FACTORS",
    "Alternative",
    "alternatives",
    "scale_lengths",
    "scale_revolute",
    "shift_pairing",
    "swap_frames",
    "swap_joints",
]
