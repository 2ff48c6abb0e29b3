"""Pairing a bag's measurements with its joint readings: samples, nearest readings, the rest rule.

**Samples.** Measurement messages (poses of different frames, or images of different cameras)
whose stamps lie within ``sync_tolerance`` of the first of them form one **sample** (a frame or
camera seen twice starts a new sample).

**Pairing and rest.** A sample's stamp is the mean of its messages' stamps. For each joint the
reading nearest to it is used; it must be within ``sync_tolerance``, else the bag is refused
(naming the sample, the joint and the gap). The joints must be at rest around the sample: every
reading of each joint within ``rest_window`` of the stamp must agree with the one used within
``rest_tolerance_m`` (prismatic) / ``rest_tolerance_rad`` (revolute), and there must be readings
strictly before and strictly after the stamp inside the window; otherwise the sample is skipped
and listed. ``rest_window = 0`` turns the rest check off (one reading per configuration).

Samples are numbered in time order over the whole bag (``sample 3``), whatever later steps leave
out. See ``docs/bags.md``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from cpc2urdf.errors import ConfigurationError, InputFileError
from cpc2urdf.files.spec import RobotSpec
from cpc2urdf.identification.vision.bags.bag_reader import NS, Message, Series
from cpc2urdf.model import CPCModel, RobotStructure
from cpc2urdf.urdf.robot import UrdfRobot, urdf_source

Array = NDArray[np.float64]

SYNC_TOLERANCE = (
    0.02  # [s]: a measurement's nearest joint reading, and the messages of one sample, this close
)
REST_WINDOW = 0.1  # [s]: joint readings this close to a sample must show the joint at rest
REST_TOLERANCE_M = 1e-5  # [m]: a prismatic joint at rest varies less than this over the rest window
REST_TOLERANCE_RAD = 1.7453292519943296e-4  # [rad] (0.01 deg): same for a revolute joint
LIMIT_SLACK = 1e-9  # [m] or [rad]: a reading this far outside its joint's limits is still accepted, as in measurement files


@dataclass(frozen=True)
class SyncRule:
    """How measurements are paired with joint readings (module docstring).

    Attributes:
        sync_tolerance: [s] the largest gap between a sample and each joint's nearest reading,
            and between the messages of one sample.
        rest_window: [s] readings this close to a sample must agree (0: no rest check).
        rest_tolerance_m: [m] agreement of a prismatic joint's readings.
        rest_tolerance_rad: [rad] agreement of a revolute joint's readings.
    """

    sync_tolerance: float = SYNC_TOLERANCE
    rest_window: float = REST_WINDOW
    rest_tolerance_m: float = REST_TOLERANCE_M
    rest_tolerance_rad: float = REST_TOLERANCE_RAD

    def __post_init__(self) -> None:
        for name in ("sync_tolerance", "rest_window", "rest_tolerance_m", "rest_tolerance_rad"):
            v = getattr(self, name)
            if not np.isfinite(v) or v < 0 or (name == "sync_tolerance" and v == 0):
                raise ConfigurationError(
                    f"{name} must be a finite number >= 0 (> 0 for sync_tolerance), got {v!r}"
                )


@dataclass
class BagSamples:
    """Samples of a bag paired with joint readings.

    Attributes:
        stamps_ns: Each kept sample's stamp [ns since the epoch], shape (N,).
        labels: One label per kept sample (``t=<sec>.<nsec>``).
        q: Joint readings [m]/[rad], shape (N, n), in the order of ``joints``.
        joints: The joint names (as ``/joint_states`` names them).
        skipped: One line per sample left out (joints moving, a camera missing), naming it and why.
        bag_time_messages: How many messages had no header stamp and were placed at the bag's time.
        n_messages: Measurement messages read (poses or images).
    """

    stamps_ns: list[int]
    labels: list[str]
    q: Array
    joints: list[str]
    skipped: list[str] = field(default_factory=list)
    bag_time_messages: int = 0
    n_messages: int = 0


def group_messages(messages: list[Message], tol_ns: int) -> list[list[Message]]:
    """Messages within ``tol_ns`` of a sample's first message form that sample; a key seen
    twice starts a new sample."""
    groups: list[list[Message]] = []
    for m in sorted(messages, key=lambda m: (m.t, m.key)):
        g = groups[-1] if groups else None
        if g is None or m.t - g[0].t > tol_ns or any(x.key == m.key for x in g):
            groups.append([m])
        else:
            g.append(m)
    return groups


def check_topic_options(
    names: Sequence[str], option: str, topic_kind: str, name_kind: str, metavar: str
) -> None:
    """Refuse an empty topic list or a name given twice (``names``: one per ``option`` given).

    Raises:
        ConfigurationError: ``no <topic_kind> topic: give at least one <option> <metavar>``, or
            ``<option>: <name_kind> <name> given twice``.
    """
    if not names:
        raise ConfigurationError(f"no {topic_kind} topic: give at least one {option} {metavar}")
    if len(set(names)) != len(names):
        raise ConfigurationError(
            f"{option}: {name_kind} {next(n for n in names if names.count(n) > 1)!r} given twice"
        )


def stamp_label(t_ns: int) -> str:
    return f"t={t_ns // NS}.{t_ns % NS:09d}"


def pair_samples(
    bag: Path,
    groups: list[list[Message]],
    series: Mapping[str, Series],
    kinds: Mapping[str, str],
    rule: SyncRule,
    joint_topic: str,
    numbers: Sequence[int] | None = None,
) -> tuple[list[int], Array, list[str], list[int]]:
    """Joint readings of each sample (nearest reading, rest check); returns kept stamps, q, skip
    lines and the kept groups' indices (in ``groups``).

    ``numbers`` are the groups' sample numbers among all of the bag's samples (default: their
    indices), so that a caller that left some samples out names the others as the bag numbers them.

    Raises:
        InputFileError: A sample with no reading of some joint within the sync tolerance.
    """
    tol = int(round(rule.sync_tolerance * NS))
    window = int(round(rule.rest_window * NS))
    stamps, rows, skipped, kept = [], [], [], []
    for gi, g in enumerate(groups):
        t = sum(m.t for m in g) // len(g)  # integer ns: a float would lose them
        what = f"sample {gi if numbers is None else numbers[gi]} ({stamp_label(t)}: {', '.join(m.where for m in g)})"
        q, why = [], ""
        for j, s in series.items():
            i = int(np.searchsorted(s.t, t))
            near = min(
                (k for k in (i - 1, i) if 0 <= k < len(s.t)), key=lambda k: abs(int(s.t[k]) - t)
            )
            gap = abs(int(s.t[near]) - t)
            if gap > tol:
                raise InputFileError(
                    bag,
                    f"{what}: no {joint_topic} reading of {j} within the sync tolerance "
                    f"{rule.sync_tolerance:g} s (nearest {gap / NS:.6g} s away); "
                    "unsynchronised clocks or a gap in the recording?",
                )
            q.append(float(s.v[near]))
            if window > 0 and not why:
                inside = (s.t >= t - window) & (s.t <= t + window)
                if not (np.any(inside & (s.t < t)) and np.any(inside & (s.t > t))):
                    why = (
                        f"{j} has no reading both before and after it within the rest window "
                        f"{rule.rest_window:g} s, so rest cannot be checked"
                    )
                else:
                    spread = float(np.max(np.abs(s.v[inside] - s.v[near])))
                    limit = (
                        rule.rest_tolerance_m
                        if kinds[j] == "prismatic"
                        else rule.rest_tolerance_rad
                    )
                    if spread > limit:
                        unit, scale = (
                            ("mm", 1e3) if kinds[j] == "prismatic" else ("deg", 180 / np.pi)
                        )
                        why = (
                            f"{j} moved {spread * scale:.4g} {unit} within {rule.rest_window:g} s "
                            f"(rest tolerance {limit * scale:.4g} {unit})"
                        )
        if why:
            skipped.append(f"{what}: joints not at rest: {why}")
            continue
        stamps.append(t)
        rows.append(q)
        kept.append(gi)
    return stamps, np.array(rows, dtype=float).reshape(len(rows), len(series)), skipped, kept


def joint_names_for(
    robot: RobotSpec | CPCModel, frames: Sequence[str]
) -> tuple[list[str], dict[str, str], dict[str, str]]:
    """The ``/joint_states`` names the robot needs (a URDF: the joints on the paths to ``frames``;
    a model made from a URDF: the URDF's names of its joints), their types, and the model name of each."""
    if isinstance(robot, UrdfRobot) and robot.names is not None:
        r = robot.restricted(frames) if frames else robot
        assert r.names is not None
        names = {r.names.urdf_joint(n): n for n in r.structure.joint_names}
        s = r.structure
    elif isinstance(robot, CPCModel):
        s = robot.structure
        src = urdf_source(robot)
        names = {(src.joints.get(n, n) if src is not None else n): n for n in s.joint_names}
    else:
        s = robot.structure
        names = {n: n for n in s.joint_names}
    kinds = {f: s.joint(m).type for f, m in names.items()}
    return list(names), kinds, names


def check_limits(
    bag: Path,
    structure: RobotStructure,
    q: Array,
    columns: Sequence[int],
    joints: Sequence[str],
    labels: Sequence[str],
) -> None:
    """Refuse a reading outside its joint's limits (what ``cpc2urdf measure`` and the hand-eye
    pose files would refuse), naming the sample and the joint as ``/joint_states`` names it.

    Args:
        bag: The bag, for the message.
        structure: The robot.
        q: Readings [m]/[rad], shape (N, len(joints)).
        columns: For each joint of ``structure``, its column in ``q``.
        joints: The ``/joint_states`` name of each column.
        labels: One label per row.

    Raises:
        InputFileError: The first reading outside its limits.
    """
    for k, j in enumerate(structure.joints):
        c = columns[k]
        bad = np.flatnonzero((q[:, c] < j.lower - LIMIT_SLACK) | (q[:, c] > j.upper + LIMIT_SLACK))
        if bad.size:
            i = int(bad[0])
            raise InputFileError(
                bag,
                f"{labels[i]}: {joints[c]} = {q[i, c]:.6g} is outside "
                f"the joint limits [{j.lower:.6g}, {j.upper:.6g}] (m or rad)",
            )


def provenance(
    bag: Path,
    joint_topic: str,
    rule: SyncRule,
    samples: BagSamples,
    topics: Mapping[str, str],
    kind: str,
) -> dict[str, Any]:
    return {
        "source": "ros bag",
        "bag": str(bag),
        "joint_states": joint_topic,
        kind: dict(topics),
        "sync_tolerance_s": rule.sync_tolerance,
        "rest_window_s": rule.rest_window,
        "rest_tolerance_m": rule.rest_tolerance_m,
        "rest_tolerance_rad": rule.rest_tolerance_rad,
        "messages": samples.n_messages,
        "messages_at_bag_time": samples.bag_time_messages,
        "skipped": list(samples.skipped),
    }


__all__ = [
    "LIMIT_SLACK",
    "REST_TOLERANCE_M",
    "REST_TOLERANCE_RAD",
    "REST_WINDOW",
    "SYNC_TOLERANCE",
    "BagSamples",
    "SyncRule",
    "check_limits",
    "check_topic_options",
    "group_messages",
    "joint_names_for",
    "pair_samples",
    "provenance",
    "stamp_label",
]
