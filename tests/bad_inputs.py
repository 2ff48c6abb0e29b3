"""The bad-input corpus: what a hostile or careless user gives each command.

:class:`Corpus` holds the clean inputs every case starts from (a simulated IIS-head measurement, its
held-out file, the model identified from it, the IIS-head URDF and spec, a clean hand-eye pose file,
a small blank image folder with its rig and camera files); :data:`CASES` are the broken ones. A case
is one command line, the file it breaks (``{bad}``, written into the case's own folder) and the words
its one-line refusal must contain: the file, field, joint or option at fault.

Placeholders in ``argv`` and ``expected``: ``{bad}`` the broken file, ``{tmp}`` the case's folder,
``{out}`` an output path in it that must not appear, and the clean inputs ``{meas}``, ``{heldout}``,
``{model}``, ``{urdf}``, ``{spec}``, ``{poses}``, ``{images}``, ``{rig}``, ``{joints}``, ``{camera}``.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import handeye_mistakes as hm
import stage1_mistakes as sm

Doc = dict[str, Any]


class Missing:
    """``{bad}`` does not exist."""


class Folder:
    """``{bad}`` is an empty folder."""


#: What a case writes at ``{bad}``: a JSON document (dict/list, written with ``json.dumps``, so a
#: float NaN becomes the literal ``NaN``), text, bytes, :class:`Missing`, :class:`Folder`, or a
#: function that builds a folder tree at the path.
Content = Doc | list[Any] | str | bytes | type[Missing] | type[Folder] | Callable[[Path], None]


@dataclass
class Corpus:
    """The clean inputs (paths by placeholder name) and their documents."""

    paths: dict[str, Path]
    meas: Doc
    heldout: Doc
    model: Doc
    spec: Doc
    poses: Doc
    urdf: str
    rig: str
    joints: str
    camera: str


@dataclass(frozen=True)
class Case:
    """One bad input: ``cpc2urdf ARGV`` must exit 2 with one line containing ``expected``.

    Attributes:
        id: Unique name, ``command-what``.
        argv: The command line (placeholders above).
        expected: Words the error line must contain (placeholders above).
        bad: What ``{bad}`` holds, from the clean corpus; None if the case has no ``{bad}``.
        name: File name of ``{bad}``.
    """

    id: str
    argv: tuple[str, ...]
    expected: str
    bad: Callable[[Corpus], Content] | None = None
    name: str = "bad.json"

    @property
    def command(self) -> str:
        return self.argv[0]


NO_PLATE_URDF = """<?xml version="1.0"?>
<robot name="arm">
  <link name="base"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <link name="l1"/>
</robot>
"""  # a robot with nothing to measure: no plate link


def write_content(path: Path, content: Content) -> None:
    """Put ``content`` at ``path`` (see :data:`Content`)."""
    if content is Missing:
        return
    if content is Folder:
        path.mkdir()
    elif isinstance(content, bytes):
        path.write_bytes(content)
    elif isinstance(content, str):
        path.write_text(content, encoding="utf-8")
    elif isinstance(content, (dict, list)):
        path.write_text(json.dumps(content), encoding="utf-8")
    elif not isinstance(content, type):
        content(path)


# ---- document edits -----------------------------------------------------------------------------


def edit(doc: Doc, fn: Callable[[Doc], object]) -> Doc:
    """A deep copy of ``doc`` changed in place by ``fn``."""
    d = copy.deepcopy(doc)
    fn(d)
    return d


def drop(doc: Doc, *keys: str) -> Doc:
    return edit(doc, lambda d: [d.pop(k) for k in keys])


def put(doc: Doc, **items: Any) -> Doc:
    return edit(doc, lambda d: d.update(items))


def with_duplicate_key(doc: Doc, key: str = "format") -> str:
    """The document's text with ``key`` written twice in the top-level object."""
    text = json.dumps(doc)
    return "{" + json.dumps(key) + ": " + json.dumps(doc.get(key, 0)) + ", " + text[1:]


DEEP = "[" * 100000 + "]" * 100000
PNG = b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00\x00\x10"
NAN = math.nan


def truncated(doc: Doc | str) -> str:
    text = doc if isinstance(doc, str) else json.dumps(doc, indent=1)
    return text[: len(text) // 2]


def record(doc: Doc, k: int) -> Doc:
    r: Doc = doc["records"][k]
    return r


def pose_matrix(doc: Doc, k: int, frame: str) -> list[list[float]]:
    m: list[list[float]] = record(doc, k)["poses"][frame]["matrix"]
    return m


def set_reading(doc: Doc, k: int, joint: str, value: Any) -> Doc:
    return edit(doc, lambda d: record(d, k)["joints"].__setitem__(joint, value))


def set_pose(doc: Doc, k: int, frame: str, value: Any) -> Doc:
    return edit(doc, lambda d: record(d, k)["poses"].__setitem__(frame, value))


def _matrix_entry(doc: Doc, k: int, frame: str, i: int, j: int, value: float) -> Doc:
    def fn(d: Doc) -> None:
        pose_matrix(d, k, frame)[i][j] = value

    return edit(doc, fn)


def spec_joint(doc: Doc, name: str, **items: Any) -> Doc:
    def fn(d: Doc) -> None:
        j = next(j for j in d["joints"] if j["name"] == name)
        for key, v in items.items():
            if v is None:
                j.pop(key, None)
            else:
                j[key] = v

    return edit(doc, fn)


def handeye_record(doc: Doc, k: int, key: str, value: Any) -> Doc:
    def fn(d: Doc) -> None:
        if value is None:
            d["records"][k].pop(key)
        else:
            d["records"][k][key] = value

    return edit(doc, fn)


def _rotation_scaled(doc: Doc) -> Doc:
    """Record 1's T_base_hand rotation block scaled by 2 (not a rotation)."""

    def fn(d: Doc) -> None:
        m = d["records"][1]["T_base_hand"]["matrix"]
        for i in range(3):
            for j in range(3):
                m[i][j] *= 2.0

    return edit(doc, fn)


# ---- file faults shared by every command that reads a file ---------------------------------------


def json_file_faults(
    prefix: str,
    argv: tuple[str, ...],
    good: Callable[[Corpus], Doc],
    fmt: str,
    nan: tuple[Callable[[Doc], Doc], str] | None,
) -> list[Case]:
    """The file-level faults of a JSON input at ``{bad}`` in ``argv``: missing, a folder, empty,
    binary, UTF-16, truncated, not JSON, not an object, wrong format tag, wrong version, a
    duplicate key, nesting 100,000 deep, a NaN literal in a numeric field (``nan``: the edit and
    the field's path)."""
    other = fmt.partition("@")[0] + "@99"
    cases = [
        Case(f"{prefix}-missing", argv, "{bad}: no such file", lambda c: Missing),
        Case(f"{prefix}-folder", argv, "{bad}: is a folder", lambda c: Folder),
        Case(f"{prefix}-empty", argv, "{bad}: not valid JSON (line 1, column 1", lambda c: ""),
        Case(f"{prefix}-binary", argv, "{bad}: is a binary file", lambda c: PNG),
        Case(
            f"{prefix}-utf16",
            argv,
            "{bad}: is UTF-16 text",
            lambda c: json.dumps(good(c)).encode("utf-16"),
        ),
        Case(
            f"{prefix}-truncated", argv, "{bad}: not valid JSON (line", lambda c: truncated(good(c))
        ),
        Case(
            f"{prefix}-not-json",
            argv,
            "{bad}: not valid JSON (line 1, column 1",
            lambda c: "format: yaml?\n",
        ),
        Case(f"{prefix}-list", argv, "{bad}: ", lambda c: [good(c)]),
        Case(
            f"{prefix}-format",
            argv,
            "{bad}: format is 'something/else@1'",
            lambda c: put(good(c), format="something/else@1"),
        ),
        Case(
            f"{prefix}-version",
            argv,
            f"{{bad}}: format is '{other}'",
            lambda c: put(good(c), format=other),
        ),
        Case(f"{prefix}-no-format", argv, "{bad}: ", lambda c: drop(good(c), "format")),
        Case(
            f"{prefix}-duplicate-key",
            argv,
            "{bad}: duplicate key 'format'",
            lambda c: with_duplicate_key(good(c)),
        ),
        Case(f"{prefix}-deep", argv, "{bad}: nested more than 64 levels deep", lambda c: DEEP),
    ]
    if nan is not None:  # json.dumps writes a float NaN as the literal NaN
        fn, where = nan
        cases.append(
            Case(
                f"{prefix}-nan",
                argv,
                f"{{bad}}: {where}: non-finite number NaN",
                lambda c: fn(good(c)),
            )
        )
        cases.append(
            Case(
                f"{prefix}-infinity",
                argv,
                f"{{bad}}: {where}: non-finite number -Infinity",
                lambda c: json.dumps(fn(good(c))).replace("NaN", "-Infinity"),
            )
        )
        cases.append(
            Case(
                f"{prefix}-overflow",
                argv,
                f"{{bad}}: {where}: number 1e999 is out of range",
                lambda c: json.dumps(fn(good(c))).replace("NaN", "1e999"),
            )
        )
    return cases


def urdf_file_faults(prefix: str, argv: tuple[str, ...]) -> list[Case]:
    """The file-level faults of a URDF at ``{bad}`` (named ``bad.urdf``)."""

    def visual_nan(c: Corpus) -> str:
        return c.urdf.replace('<box size="0.12 0.12 0.01"/>', '<box size="0.12 0.12 nan"/>', 1)

    return [
        Case(f"{prefix}-missing", argv, "{bad}: no such file", lambda c: Missing, name="bad.urdf"),
        Case(f"{prefix}-folder", argv, "{bad}: is a folder", lambda c: Folder, name="bad.urdf"),
        Case(f"{prefix}-empty", argv, "{bad}: is empty", lambda c: "", name="bad.urdf"),
        Case(f"{prefix}-binary", argv, "{bad}: is a binary file", lambda c: PNG, name="bad.urdf"),
        Case(
            f"{prefix}-not-xml",
            argv,
            "{bad}: not well-formed XML",
            lambda c: "this is not a URDF",
            name="bad.urdf",
        ),
        Case(
            f"{prefix}-truncated",
            argv,
            "{bad}: not well-formed XML",
            lambda c: truncated(c.urdf),
            name="bad.urdf",
        ),
        Case(
            f"{prefix}-missing-link",
            argv,
            "{bad}: joint 'table_y': parent link 'nope' is not a link",
            lambda c: c.urdf.replace('<parent link="table_x_link"/>', '<parent link="nope"/>'),
            name="bad.urdf",
        ),
        Case(
            f"{prefix}-nan-box",
            argv,
            "{bad}: link 'base': visual 'base_plate' geometry box size",
            visual_nan,
            name="bad.urdf",
        ),
        Case(
            f"{prefix}-sdf",
            argv,
            "{bad}: the root element is <sdf>, expected <robot>",
            lambda c: '<sdf version="1.6"><model name="m"/></sdf>',
            name="bad.urdf",
        ),
    ]


def robot_ref_faults(prefix: str, argv: tuple[str, ...]) -> list[Case]:
    """A robot reference (model file, spec, shipped name) at ``{bad}``: the file faults of a
    model file, plus specs that describe impossible robots."""
    cases = json_file_faults(
        prefix,
        argv,
        lambda c: c.model,
        "cpc2urdf/model@1",
        (lambda d: edit(d, lambda x: x["joints"][0].__setitem__("lower", NAN)), "joints[0].lower"),
    )
    return cases + [
        Case(
            f"{prefix}-unknown-parent",
            argv,
            "{bad}: ",
            lambda c: spec_joint(c.spec, "pan", parent="neck"),
            name="spec.json",
        ),
        Case(
            f"{prefix}-limits-inverted",
            argv,
            "pan",
            lambda c: spec_joint(c.spec, "pan", lower=180, upper=0),
            name="spec.json",
        ),
        Case(
            f"{prefix}-joint-type",
            argv,
            "hinge",
            lambda c: spec_joint(c.spec, "pan", type="hinge"),
            name="spec.json",
        ),
        Case(
            f"{prefix}-no-joints",
            argv,
            "joints",
            lambda c: drop(c.spec, "joints"),
            name="spec.json",
        ),
        Case(
            f"{prefix}-length-unit",
            argv,
            "milimetre",
            lambda c: put(c.spec, units={"length": "milimetre", "angle": "deg"}),
            name="spec.json",
        ),
        Case(
            f"{prefix}-negative-density",
            argv,
            "density",
            lambda c: put(c.spec, density=-2700),
            name="spec.json",
        ),
        Case(
            f"{prefix}-string-limit",
            argv,
            "upper",
            lambda c: spec_joint(c.spec, "tilt", upper="60"),
            name="spec.json",
        ),
        Case(
            f"{prefix}-no-such-robot",
            tuple(a.replace("{bad}", "no_such_robot") for a in argv),
            "no_such_robot: no such file, and not a shipped robot name",
        ),
    ]


# ---- the cases, command by command --------------------------------------------------------------

MEAS = "cpc2urdf/measurements@1"
OUT_JSON = "{out}.json"


def _identify() -> list[Case]:
    argv = ("identify", "{bad}", "-o", OUT_JSON)
    nan = (lambda d: set_reading(d, 3, "pan", NAN), "records[3].joints.pan")
    cases = json_file_faults("identify", argv, lambda c: c.meas, MEAS, nan)
    m = lambda fn: lambda c: fn(c.meas)  # noqa: E731 - a case's content from the measurement file
    cases += [
        Case("identify-no-records", argv, "records", m(lambda d: drop(d, "records"))),
        Case("identify-empty-records", argv, "records", m(lambda d: put(d, records=[]))),
        Case("identify-records-object", argv, "records", m(lambda d: put(d, records={"a": 1}))),
        Case(
            "identify-record-no-joints",
            argv,
            "records[4]",
            m(lambda d: edit(d, lambda x: record(x, 4).pop("joints"))),
        ),
        Case(
            "identify-record-no-poses",
            argv,
            "records[4]",
            m(lambda d: edit(d, lambda x: record(x, 4).pop("poses"))),
        ),
        Case(
            "identify-reading-string",
            argv,
            "records[2].joints.pan",
            m(lambda d: set_reading(d, 2, "pan", "90")),
        ),
        Case(
            "identify-reading-bool",
            argv,
            "records[2].joints.tilt",
            m(lambda d: set_reading(d, 2, "tilt", True)),
        ),
        Case(
            "identify-reading-null",
            argv,
            "records[2].joints.tilt",
            m(lambda d: set_reading(d, 2, "tilt", None)),
        ),
        Case(
            "identify-reading-out-of-limits",
            argv,
            "tilt",
            m(lambda d: set_reading(d, 5, "tilt", 4.0)),
        ),
        Case(
            "identify-reading-huge",
            argv,
            "table_x",
            m(lambda d: set_reading(d, 5, "table_x", 1e300)),
        ),
        Case("identify-unknown-joint", argv, "neck", m(lambda d: set_reading(d, 1, "neck", 0.1))),
        Case(
            "identify-missing-joint",
            argv,
            "pan",
            m(lambda d: edit(d, lambda x: [r["joints"].pop("pan") for r in x["records"][6:8]])),
        ),
        Case(
            "identify-unknown-frame",
            argv,
            "plate_middle",
            m(lambda d: set_pose(d, 2, "plate_middle", record(d, 2)["poses"]["plate_left"])),
        ),
        Case(
            "identify-pose-not-rotation",
            argv,
            "records[1].poses.plate_left",
            m(lambda d: _matrix_entry(d, 1, "plate_left", 0, 0, 2.0)),
        ),
        Case(
            "identify-pose-bottom-row",
            argv,
            "records[1].poses.plate_left",
            m(lambda d: _matrix_entry(d, 1, "plate_left", 3, 0, 0.5)),
        ),
        Case(
            "identify-pose-3x4",
            argv,
            "records[1].poses.plate_left",
            m(
                lambda d: set_pose(
                    d, 1, "plate_left", {"matrix": pose_matrix(d, 1, "plate_left")[:3]}
                )
            ),
        ),
        Case(
            "identify-pose-nan",
            argv,
            "records[1].poses.plate_left",
            m(lambda d: _matrix_entry(d, 1, "plate_left", 0, 3, NAN)),
        ),
        Case(
            "identify-pose-string",
            argv,
            "records[1].poses.plate_left",
            m(lambda d: set_pose(d, 1, "plate_left", "identity")),
        ),
        Case(
            "identify-quaternion-length",
            argv,
            "records[1].poses.plate_left",
            m(lambda d: set_pose(d, 1, "plate_left", {"xyz": [0, 0, 1], "quat_xyzw": [0, 0, 1]})),
        ),
        Case(
            "identify-quaternion-zero",
            argv,
            "records[1].poses.plate_left",
            m(
                lambda d: set_pose(
                    d, 1, "plate_left", {"xyz": [0, 0, 1], "quat_xyzw": [0, 0, 0, 0]}
                )
            ),
        ),
        Case(
            "identify-length-unit-typo",
            argv,
            "milimeters",
            m(lambda d: put(d, units={"length": "milimeters", "angle": "rad"})),
        ),
        Case(
            "identify-angle-unit-typo",
            argv,
            "degree",
            m(lambda d: put(d, units={"length": "m", "angle": "degree"})),
        ),
        Case("identify-units-string", argv, "units", m(lambda d: put(d, units="mm"))),
        Case(
            "identify-noise-negative",
            argv,
            "noise.sigma_t_m: expected a positive number",
            m(lambda d: put(d, noise={**d["noise"], "sigma_t_m": -0.0005})),
        ),
        Case(
            "identify-noise-zero",
            argv,
            "noise.sigma_t_m: expected a positive number",
            m(lambda d: put(d, noise={**d["noise"], "sigma_t_m": 0.0, "sigma_r_rad": 0.0})),
        ),
        Case(
            "identify-noise-string",
            argv,
            "noise.sigma_t_m: expected a positive number",
            m(lambda d: put(d, noise={**d["noise"], "sigma_t_m": "0.5 mm"})),
        ),
        Case(
            "identify-unknown-robot",
            argv,
            "no_such_robot",
            m(lambda d: put(d, robot="no_such_robot")),
        ),
        Case(
            "identify-robot-missing-file", argv, "nope.json", m(lambda d: put(d, robot="nope.json"))
        ),
        Case("identify-robot-number", argv, "robot", m(lambda d: put(d, robot=42))),
        # degenerate data (stage1_mistakes: the mistakes of the gate study)
        Case(
            "identify-joint-never-moved",
            argv,
            "joint 'tilt' has fewer than two distinct readings",
            m(sm.joint_never_moved),
        ),
        Case("identify-only-q0", argv, "no joint moves", m(sm.only_q0)),
        Case("identify-q0-copies", argv, "no joint moves", m(sm.q0_copies)),
        Case("identify-duplicated-records", argv, "to the last digit", m(sm.duplicated_records)),
        # the consistency gate: about a second each, so a few (radians labelled deg takes ~30 s of
        # CPU on this robot and is left to tests/test_cli_identify.py's smaller one)
        Case(
            "identify-metres-as-mm",
            argv,
            "lengths look like metres labelled mm",
            m(sm.metres_as_mm),
        ),
        Case(
            "identify-plates-swapped",
            argv,
            "the poses of plate_left and plate_right look swapped",
            m(sm.plates_swapped),
        ),
        Case("identify-poses-inverted", argv, "inverted", m(sm.poses_inverted)),
        # the command line
        Case(
            "identify-unknown-method",
            ("identify", "{meas}", "-o", OUT_JSON, "--method", "magic"),
            "invalid choice: 'magic'",
        ),
        Case("identify-no-output", ("identify", "{meas}"), "-o/--output"),
        Case(
            "identify-output-missing-folder",
            ("identify", "{meas}", "-o", "{tmp}/no/such/model.json"),
            "folder {tmp}/no/such does not exist",
        ),
        Case(
            "identify-output-is-folder",
            ("identify", "{meas}", "-o", "{bad}"),
            "{bad}: is a folder, expected a file path",
            lambda c: Folder,
            name="out",
        ),
        Case(
            "identify-robot-option-missing",
            ("identify", "{meas}", "-o", OUT_JSON, "--robot", "{tmp}/nope.json"),
            "{tmp}/nope.json: no such file",
        ),
        Case(
            "identify-robot-option-unknown",
            ("identify", "{meas}", "-o", OUT_JSON, "--robot", "my_head"),
            "my_head: no such file, and not a shipped robot name",
        ),
    ]
    cases += [
        Case(c.id.replace("spec-", "identify-robot-"), c.argv, c.expected, c.bad, c.name)
        for c in robot_ref_faults(
            "spec", ("identify", "{meas}", "-o", OUT_JSON, "--robot", "{bad}")
        )
        if c.id.endswith(
            (
                "-missing",
                "-folder",
                "-not-json",
                "-unknown-parent",
                "-limits-inverted",
                "-no-joints",
            )
        )
    ]
    return cases


def _accuracy() -> list[Case]:
    held = ("accuracy", "{model}", "{bad}")
    nan = (
        lambda d: _matrix_entry(d, 2, "plate_right", 1, 3, NAN),
        "records[2].poses.plate_right.matrix[1][3]",
    )
    cases = json_file_faults("accuracy-heldout", held, lambda c: c.heldout, MEAS, nan)
    cases += [
        c
        for c in robot_ref_faults("accuracy-model", ("accuracy", "{bad}", "{heldout}"))
        if not c.id.endswith(
            ("-empty", "-utf16", "-no-format", "-string-limit", "-negative-density")
        )
    ]
    h = lambda fn: lambda c: fn(c.heldout)  # noqa: E731
    cases += [
        Case(
            "accuracy-heldout-unknown-frame",
            held,
            "plate_middle",
            h(
                lambda d: edit(
                    d,
                    lambda x: [
                        r["poses"].__setitem__("plate_middle", r["poses"].pop("plate_left"))
                        for r in x["records"]
                    ],
                )
            ),
        ),
        Case(
            "accuracy-heldout-unknown-joint",
            held,
            "neck",
            h(lambda d: set_reading(d, 0, "neck", 0.0)),
        ),
        Case(
            "accuracy-heldout-out-of-limits",
            held,
            "vergence_left",
            h(lambda d: set_reading(d, 1, "vergence_left", -2.0)),
        ),
        Case("accuracy-heldout-no-records", held, "records", h(lambda d: put(d, records=[]))),
        Case(
            "accuracy-heldout-other-robot",
            held,
            "no_such_robot",
            h(lambda d: put(d, robot="no_such_robot")),
        ),
        Case(
            "accuracy-heldout-is-model",
            ("accuracy", "{model}", "{model}"),
            "{model}: format is 'cpc2urdf/model@1'",
        ),
        Case(
            "accuracy-model-is-measurements",
            ("accuracy", "{meas}", "{heldout}"),
            "{meas}: format is 'cpc2urdf/measurements@1'",
        ),
        Case("accuracy-heldout-metres-as-mm", held, "{bad}", h(sm.metres_as_mm)),
        Case("accuracy-missing-argument", ("accuracy", "{model}"), "heldout"),
    ]
    return cases


def _handeye() -> list[Case]:
    argv = ("handeye", "{bad}")
    nan = (
        lambda d: edit(
            d, lambda x: x["records"][0]["T_base_hand"]["matrix"][0].__setitem__(3, NAN)
        ),
        "records[0].T_base_hand.matrix[0][3]",
    )
    cases = json_file_faults("handeye", argv, lambda c: c.poses, "cpc2urdf/handeye-poses@1", nan)
    p = lambda fn: lambda c: fn(c.poses)  # noqa: E731
    cases += [
        Case("handeye-no-records", argv, "records", p(lambda d: drop(d, "records"))),
        Case("handeye-empty-records", argv, "records", p(lambda d: put(d, records=[]))),
        Case(
            "handeye-two-records", argv, "at least 3", p(lambda d: put(d, records=d["records"][:2]))
        ),
        Case(
            "handeye-record-lacks-camera",
            argv,
            "records[2] lacks 'T_camera_target'",
            p(lambda d: handeye_record(d, 2, "T_camera_target", None)),
        ),
        Case("handeye-not-rotation", argv, "records[1].T_base_hand", p(_rotation_scaled)),
        Case(
            "handeye-matrix-string",
            argv,
            "records[0].T_camera_target",
            p(lambda d: handeye_record(d, 0, "T_camera_target", "eye(4)")),
        ),
        Case(
            "handeye-quat-length",
            argv,
            "records[0].T_base_hand",
            p(
                lambda d: handeye_record(
                    d, 0, "T_base_hand", {"xyz": [0, 0, 0], "quat_xyzw": [0, 0, 0, 1, 0]}
                )
            ),
        ),
        Case(
            "handeye-length-unit-typo",
            argv,
            "mmm",
            p(lambda d: put(d, units={"length": "mmm", "angle": "deg"})),
        ),
        Case(
            "handeye-duplicated-records",
            argv,
            "{bad}: records[12] repeats records[0] to the last digit (T_base_hand and T_camera_target) (and 11 more copies)",
            p(lambda d: put(d, records=d["records"] + copy.deepcopy(d["records"]))),
        ),
        Case(
            "handeye-identical-poses",
            argv,
            "{bad}: records[1] repeats records[0] to the last digit",
            p(lambda d: put(d, records=[copy.deepcopy(d["records"][0]) for _ in range(6)])),
        ),
        Case(
            "handeye-unknown-method",
            ("handeye", "{poses}", "--method", "magic"),
            "invalid choice: 'magic'",
        ),
        Case(
            "handeye-model-without-output",
            ("handeye", "{poses}", "--model", "{model}"),
            "--model and -o/--output go together",
        ),
        Case(
            "handeye-model-all",
            ("handeye", "{poses}", "--model", "{model}", "-o", OUT_JSON, "--method", "all"),
            "--model needs one --method",
        ),
        Case(
            "handeye-unknown-hand",
            ("handeye", "{poses}", "--model", "{model}", "-o", OUT_JSON, "--hand", "nose"),
            "nose",
        ),
        Case(
            "handeye-camera-is-plate",
            ("handeye", "{poses}", "--model", "{model}", "-o", OUT_JSON, "--camera", "plate_left"),
            "plate_left",
        ),
        Case(
            "handeye-output-missing-folder",
            ("handeye", "{poses}", "--model", "{model}", "-o", "{tmp}/no/m.json"),
            "folder {tmp}/no does not exist",
        ),
        Case(
            "handeye-output-is-folder",
            ("handeye", "{poses}", "--model", "{model}", "-o", "{bad}"),
            "{bad}: is a folder",
            lambda c: Folder,
            name="out",
        ),
        Case(
            "handeye-model-missing",
            ("handeye", "{poses}", "--model", "{tmp}/nope.json", "-o", OUT_JSON),
            "{tmp}/nope.json: no such file",
        ),
        Case(
            "handeye-model-not-json",
            ("handeye", "{poses}", "--model", "{bad}", "-o", OUT_JSON),
            "{bad}: not valid JSON",
            lambda c: "{",
        ),
    ]
    for mistake, _, words in hm.MISTAKES[:6] + hm.MISTAKES[8:10] + hm.MISTAKES[11:]:
        cases.append(
            Case(
                f"handeye-{mistake.__name__.replace('_', '-')}",
                argv,
                words,
                (lambda fn: lambda c: fn(c.poses))(mistake),
            )
        )
    # the same mistake written into a model: refused before anything is written
    cases.append(
        Case(
            "handeye-inverted-into-model",
            ("handeye", "{bad}", "--model", "{model}", "-o", OUT_JSON),
            hm.MISTAKES[0][2],
            lambda c: hm.hand_inverted(c.poses),
        )
    )
    return cases


def _export() -> list[Case]:
    cases = robot_ref_faults("export", ("export", "{bad}", "-o", "{out}.urdf"))
    cases += urdf_file_faults("export-urdf", ("export", "{bad}", "-o", "{out}.urdf"))[:5]
    cases += [
        Case(
            "export-output-missing-folder",
            ("export", "iis_head", "-o", "{tmp}/no/head.urdf"),
            "folder {tmp}/no does not exist",
        ),
        Case(
            "export-output-is-folder",
            ("export", "iis_head", "-o", "{bad}"),
            "{bad}: is a folder",
            lambda c: Folder,
            name="out",
        ),
        Case(
            "export-up-zero",
            ("export", "iis_head", "-o", "{out}.urdf", "--up", "0", "0", "0"),
            "--up",
        ),
        Case(
            "export-up-nan",
            ("export", "iis_head", "-o", "{out}.urdf", "--up", "nan", "0", "1"),
            "--up",
        ),
        Case(
            "export-up-inf",
            ("export", "iis_head", "-o", "{out}.urdf", "--up", "0", "inf", "1"),
            "--up",
        ),
        Case(
            "export-up-minus-inf",
            ("export", "iis_head", "-o", "{out}.urdf", "--up", "0", "-1e-3", "-inf"),
            "--up must be",
        ),
        Case(
            "export-up-two-values",
            ("export", "iis_head", "-o", "{out}.urdf", "--up", "0", "1"),
            "--up",
        ),
        Case(
            "export-mount-unknown",
            ("export", "iis_head", "-o", "{out}.urdf", "--mount", "ceiling"),
            "invalid choice: 'ceiling'",
        ),
        Case("export-no-output", ("export", "iis_head"), "-o/--output"),
        Case(
            "export-up-key-unknown-joint",
            ("export", "{bad}", "-o", "{out}.urdf"),
            "neck",
            lambda c: put(c.spec, up={"joint": "neck"}),
            name="spec.json",
        ),
    ]
    return cases


def _check() -> list[Case]:
    argv = ("check", "{bad}", "--model", "iis_head", "-n", "3")
    cases = urdf_file_faults("check", argv)
    cases += [
        c
        for c in robot_ref_faults("check-model", ("check", "{urdf}", "--model", "{bad}", "-n", "3"))
        if c.id.endswith(
            (
                "-missing",
                "-folder",
                "-binary",
                "-truncated",
                "-format",
                "-duplicate-key",
                "-deep",
                "-nan",
                "-unknown-parent",
                "-no-such-robot",
            )
        )
    ]
    cases += [
        Case(
            "check-configurations-zero",
            ("check", "{urdf}", "--model", "iis_head", "-n", "0"),
            "--configurations must be at least 1",
        ),
        Case(
            "check-configurations-negative",
            ("check", "{urdf}", "--model", "iis_head", "-n", "-5"),
            "--configurations",
        ),
        Case(
            "check-configurations-text",
            ("check", "{urdf}", "--model", "iis_head", "-n", "many"),
            "--configurations",
        ),
        Case(
            "check-seed-text", ("check", "{urdf}", "--model", "iis_head", "--seed", "x"), "--seed"
        ),
        Case("check-no-model", ("check", "{urdf}"), "--model"),
        Case(
            "check-joint-zero-axis",
            argv,
            "{bad}: joint 'pan': axis xyz '0 0 0' is zero",
            lambda c: _in_joint(c.urdf, "pan", '<axis xyz="', '<axis xyz="0 0 0" old="'),
            name="bad.urdf",
        ),
        Case(
            "check-xacro",
            argv,
            "{bad}: is a xacro file (<xacro:property>), not a URDF: expand it first (xacro FILE > FILE.urdf) (line",
            lambda c: c.urdf.replace("<link ", '<xacro:property name="r" value="0.1"/><link ', 1),
            name="bad.urdf",
        ),
        Case(
            "check-joint-type-unknown",
            argv,
            "{bad}: joint 'pan': type 'hinge'",
            lambda c: _in_joint(c.urdf, "pan", 'type="revolute"', 'type="hinge"'),
            name="bad.urdf",
        ),
        Case(
            "check-negative-box",
            argv,
            "{bad}: link 'base': visual 'base_plate' geometry box size '0.12 -0.12 0.01' is negative",
            lambda c: c.urdf.replace(
                '<box size="0.12 0.12 0.01"/>', '<box size="0.12 -0.12 0.01"/>', 1
            ),
            name="bad.urdf",
        ),
        Case(
            "check-negative-mass",
            argv,
            "{bad}: link 'base': inertial mass value '-2' is negative",
            lambda c: c.urdf.replace(
                '<link name="base">',
                '<link name="base"><inertial><mass value="-2"/>'
                '<inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>',
                1,
            ),
            name="bad.urdf",
        ),
        Case(
            "check-utf16",
            argv,
            "{bad}: is UTF-16 text",
            lambda c: c.urdf.encode("utf-16"),
            name="bad.urdf",
        ),
    ]
    return cases


def _in_joint(urdf: str, name: str, old: str, new: str) -> str:
    i = urdf.index(f'<joint name="{name}"')
    j = urdf.index("</joint>", i)
    return urdf[:i] + urdf[i:j].replace(old, new, 1) + urdf[j:]


def _simulate() -> list[Case]:
    s = ("simulate", "iis_head", "-o", "{out}")
    cases = [
        c
        for c in robot_ref_faults("simulate-robot", ("simulate", "{bad}", "-o", "{out}"))
        if c.id.endswith(
            (
                "-missing",
                "-folder",
                "-binary",
                "-not-json",
                "-format",
                "-duplicate-key",
                "-nan",
                "-unknown-parent",
                "-limits-inverted",
                "-length-unit",
                "-no-such-robot",
            )
        )
    ]
    cases += [
        Case("simulate-M-zero", (*s, "--M", "0"), "--M"),
        Case("simulate-M-one", (*s, "--M", "1"), "--M"),
        Case("simulate-M-negative", (*s, "--M", "-3"), "--M"),
        Case("simulate-M-text", (*s, "--M", "nine"), "--M"),
        Case("simulate-sigma-negative", (*s, "--sigma-mm", "-0.5"), "--sigma-mm"),
        Case("simulate-sigma-nan", (*s, "--sigma-mm", "nan"), "--sigma-mm"),
        Case("simulate-sigma-deg-inf", (*s, "--sigma-deg", "inf"), "--sigma-deg"),
        Case(
            "simulate-pixel-sigma-negative",
            (*s, "--noise", "stereo", "--pixel-sigma", "-1"),
            "--pixel-sigma",
        ),
        Case(
            "simulate-geometry-error-nan", (*s, "--geometry-error-mm", "nan"), "--geometry-error-mm"
        ),
        Case("simulate-heldout-negative", (*s, "--heldout", "-1"), "--heldout"),
        Case("simulate-noise-unknown", (*s, "--noise", "pink"), "invalid choice: 'pink'"),
        Case("simulate-range-unknown-joint", (*s, "--range", "neck=0:10"), "neck"),
        Case("simulate-range-inverted", (*s, "--range", "pan=120:60"), "pan"),
        Case("simulate-range-outside-limits", (*s, "--range", "tilt=10:200"), "tilt"),
        Case("simulate-range-syntax", (*s, "--range", "pan:60-120"), "--range"),
        Case("simulate-range-nan", (*s, "--range", "pan=nan:120"), "pan"),
        Case("simulate-baseline-zero", (*s, "--baseline-mm", "0"), "--baseline-mm"),
        Case("simulate-distance-negative", (*s, "--distance-mm", "-1500"), "--distance-mm"),
        Case("simulate-focal-zero", (*s, "--focal-px", "0"), "--focal-px"),
        Case("simulate-seed-negative", (*s, "--seed", "-1"), "--seed"),
        Case(
            "simulate-output-is-file",
            ("simulate", "iis_head", "-o", "{bad}"),
            "{bad}",
            lambda c: "a file\n",
            name="out",
        ),
        Case("simulate-no-output", ("simulate", "iis_head"), "-o/--output"),
    ]
    return cases


def _measure() -> list[Case]:
    rig = ("measure", "{images}", "--rig", "{bad}", "-o", OUT_JSON)
    cases = [
        Case(
            "measure-images-missing",
            ("measure", "{tmp}/nowhere", "--rig", "{rig}", "-o", OUT_JSON),
            "{tmp}/nowhere",
        ),
        Case(
            "measure-images-is-file",
            ("measure", "{bad}", "--rig", "{rig}", "-o", OUT_JSON),
            "{bad}",
            lambda c: "x\n",
            name="images",
        ),
        Case(
            "measure-images-empty-folder",
            ("measure", "{bad}", "--rig", "{rig}", "-o", OUT_JSON),
            "{bad}",
            lambda c: Folder,
            name="images",
        ),
        Case(
            "measure-images-no-right",
            ("measure", "{bad}", "--rig", "{rig}", "-o", OUT_JSON),
            "right",
            lambda c: _image_tree(c, without="right"),
            name="images",
        ),
        Case(
            "measure-images-not-images",
            ("measure", "{bad}", "--rig", "{rig}", "-o", OUT_JSON, "--on-error", "stop"),
            "0000",
            lambda c: _image_tree(c, corrupt=True),
            name="images",
        ),
        Case("measure-rig-missing", rig, "{bad}: no such file", lambda c: Missing, name="rig.yaml"),
        Case("measure-rig-folder", rig, "{bad}: is a folder", lambda c: Folder, name="rig.yaml"),
        Case("measure-rig-empty", rig, "{bad}", lambda c: "", name="rig.yaml"),
        Case("measure-rig-binary", rig, "{bad}: is a binary file", lambda c: PNG, name="rig.yaml"),
        Case("measure-rig-not-yaml", rig, "{bad}", lambda c: "K1: [1, 2\n", name="rig.yaml"),
        Case("measure-rig-no-K1", rig, "K1", lambda c: _rig_without(c.rig, "K1"), name="rig.yaml"),
        Case(
            "measure-rig-nan",
            rig,
            "{bad}",
            lambda c: c.rig.replace("60.", ".Nan", 1),
            name="rig.yaml",
        ),
        Case(
            "measure-rig-deep",
            rig,
            "{bad}",
            lambda c: "%YAML:1.0\n---\nK1: " + "[" * 5000 + "]" * 5000 + "\n",
            name="rig.yaml",
        ),
        Case(
            "measure-rig-units-typo",
            rig,
            "{bad}: units must be one of",
            lambda c: c.rig.replace("units: m", "units: milimeters"),
            name="rig.yaml",
        ),
        Case(
            "measure-rig-duplicate-key",
            rig,
            "{bad}: duplicate key 'units'",
            lambda c: c.rig + "units: mm\n",
            name="rig.yaml",
        ),
        Case(
            "measure-rig-duplicate-matrix",
            rig,
            "{bad}: duplicate key 'K1'",
            lambda c: c.rig + c.rig[c.rig.index("K1:") : c.rig.index("D1:")],
            name="rig.yaml",
        ),
        Case(
            "measure-rig-not-rotation",
            rig,
            "{bad}: R is not a rotation matrix",
            lambda c: c.rig.replace(
                "data: [ 1., 0., 0., 0., 1., 0., 0., 0., 1. ]",
                "data: [ 1., 0., 0., 0., 1., 0., 0., 0., 2. ]",
            ),
            name="rig.yaml",
        ),
        Case("measure-no-rig", ("measure", "{images}", "-o", OUT_JSON), "--rig"),
        Case(
            "measure-joints-missing",
            ("measure", "{images}", "--rig", "{rig}", "--joints", "{tmp}/nope.csv", "-o", OUT_JSON),
            "{tmp}/nope.csv: no such file",
        ),
        Case(
            "measure-joints-unknown-column",
            ("measure", "{images}", "--rig", "{rig}", "--joints", "{bad}", "-o", OUT_JSON),
            "neck",
            lambda c: c.joints.replace("pan", "neck", 1),
            name="joints.csv",
        ),
        Case(
            "measure-joints-not-number",
            ("measure", "{images}", "--rig", "{rig}", "--joints", "{bad}", "-o", OUT_JSON),
            "{bad}",
            lambda c: _csv_cell(c.joints, 2, 3, "ninety"),
            name="joints.csv",
        ),
        Case(
            "measure-joints-nan",
            ("measure", "{images}", "--rig", "{rig}", "--joints", "{bad}", "-o", OUT_JSON),
            "{bad}",
            lambda c: _csv_cell(c.joints, 2, 3, "nan"),
            name="joints.csv",
        ),
        Case(
            "measure-joints-out-of-limits",
            ("measure", "{images}", "--rig", "{rig}", "--joints", "{bad}", "-o", OUT_JSON),
            "tilt",
            lambda c: _csv_cell(c.joints, 1, 5, "90"),
            name="joints.csv",
        ),
        Case(
            "measure-joints-unit-typo",
            ("measure", "{images}", "--rig", "{rig}", "--joints", "{bad}", "-o", OUT_JSON),
            "pan",
            lambda c: c.joints.replace("pan", "pan[degree]", 1),
            name="joints.csv",
        ),
        Case(
            "measure-joints-duplicate-record",
            ("measure", "{images}", "--rig", "{rig}", "--joints", "{bad}", "-o", OUT_JSON),
            "0001",
            lambda c: c.joints + c.joints.splitlines()[2] + "\n",
            name="joints.csv",
        ),
        Case(
            "measure-robot-unknown",
            ("measure", "{images}", "--rig", "{rig}", "--robot", "no_such_robot", "-o", OUT_JSON),
            "no_such_robot",
        ),
        Case(
            "measure-on-error-unknown",
            ("measure", "{images}", "--rig", "{rig}", "--on-error", "ignore", "-o", OUT_JSON),
            "invalid choice: 'ignore'",
        ),
        Case(
            "measure-output-missing-folder",
            ("measure", "{images}", "--rig", "{rig}", "-o", "{tmp}/no/m.json"),
            "folder {tmp}/no does not exist",
        ),
        Case(
            "measure-output-is-folder",
            ("measure", "{images}", "--rig", "{rig}", "-o", "{bad}"),
            "{bad}: is a folder",
            lambda c: Folder,
            name="out",
        ),
        Case(
            "measure-stage2-no-model", ("measure", "{images}", "--stage2", "-o", "{out}"), "--model"
        ),
        Case(
            "measure-stage2-model-missing",
            ("measure", "{images}", "--stage2", "--model", "{tmp}/nope.json", "-o", "{out}"),
            "{tmp}/nope.json",
        ),
        Case(
            "measure-stage2-camera-syntax",
            (
                "measure",
                "{images}",
                "--stage2",
                "--model",
                "{model}",
                "--camera",
                "camera_left_optical",
                "-o",
                "{out}",
            ),
            "--camera",
        ),
        Case(
            "measure-stage2-camera-file-missing",
            (
                "measure",
                "{images}",
                "--stage2",
                "--model",
                "{model}",
                "--camera",
                "camera_left_optical={tmp}/nope.yaml",
                "-o",
                "{out}",
            ),
            "{tmp}/nope.yaml",
        ),
        Case(
            "measure-stage2-camera-file-bad",
            (
                "measure",
                "{images}",
                "--stage2",
                "--model",
                "{model}",
                "--camera",
                "camera_left_optical={bad}",
                "-o",
                "{out}",
            ),
            "{bad}",
            lambda c: c.camera.replace("K:", "Q:"),
            name="cam.yaml",
        ),
        Case(
            "measure-stage2-unknown-camera",
            (
                "measure",
                "{images}",
                "--stage2",
                "--model",
                "{model}",
                "--camera",
                "zoom_cam={camera}",
                "-o",
                "{out}",
            ),
            "zoom_cam",
        ),
    ]
    return cases


def _image_tree(c: Corpus, *, without: str = "", corrupt: bool = False) -> Callable[[Path], None]:
    """A copy of the blank image folder, one camera folder left out or every image corrupt."""
    import shutil

    def build(path: Path) -> None:
        shutil.copytree(c.paths["images"], path)
        if without:
            shutil.rmtree(path / without)
        if corrupt:
            for png in path.rglob("*.png"):
                png.write_bytes(b"not an image")

    return build


def _rig_without(text: str, key: str) -> str:
    lines = text.splitlines(keepends=True)
    out, skip = [], False
    for line in lines:
        if line.startswith(f"{key}:"):
            skip = True
            continue
        if skip and line.startswith((" ", "\t")):
            continue
        skip = False
        out.append(line)
    return "".join(out)


def _csv_cell(text: str, row: int, col: int, value: str) -> str:
    """``text`` (a CSV with a header, ``#`` comments kept) with data row ``row``, column ``col`` replaced."""
    lines = text.splitlines()
    data = [i for i, line in enumerate(lines) if line and not line.startswith("#")]
    i = data[row]
    cells = lines[i].split(",")
    cells[col] = value
    lines[i] = ",".join(cells)
    return "\n".join(lines) + "\n"


TARGET = ("--target", "-0.6", "-0.6", "0.7")


def _gaze() -> list[Case]:
    g = ("gaze", "iis_head")
    cases = [
        c
        for c in robot_ref_faults("gaze-model", ("gaze", "{bad}", *TARGET))
        if c.id.endswith(
            (
                "-missing",
                "-folder",
                "-binary",
                "-format",
                "-duplicate-key",
                "-deep",
                "-nan",
                "-unknown-parent",
                "-no-such-robot",
            )
        )
    ]
    cases += urdf_file_faults("gaze-urdf", ("gaze", "{bad}", *TARGET))
    cases += [
        Case("gaze-target-nan", (*g, "--target", "1", "nan", "3"), "target must be finite"),
        Case("gaze-target-inf", (*g, "--target", "inf", "0", "1"), "target must be finite"),
        Case("gaze-target-two-values", (*g, "--target", "1", "2"), "--target"),
        Case("gaze-target-text", (*g, "--target", "1", "2", "x"), "--target"),
        Case("gaze-no-target", g, "--target"),
        # argparse alone took "-1e-3" for an option ("expected 3 arguments"): now a number, then refused
        Case(
            "gaze-target-exponent-nan",
            (*g, "--target", "-1e-3", "0", "nan"),
            "target must be finite, got [-0.001, 0.0, nan]",
        ),
        Case(
            "gaze-target-minus-inf",
            (*g, "--target", "-inf", "0", "1"),
            "target must be finite, got [-inf, 0.0, 1.0]",
        ),
        Case("gaze-policy-unknown", (*g, *TARGET, "--policy", "nope"), "invalid choice: 'nope'"),
        Case(
            "gaze-q-current-count",
            (*g, *TARGET, "--q-current", "1", "2"),
            "q_current must have shape (6,)",
        ),
        Case(
            "gaze-q-current-out-of-limits",
            (*g, *TARGET, "--q-current", "0.5", "0.25", "9", "0.5", "0.7", "0.7"),
            "pan",
        ),
        Case(
            "gaze-q-current-nan",
            (*g, *TARGET, "--q-current", "0.5", "0.25", "nan", "0.5", "0.7", "0.7"),
            "--q-current values must be finite, got 'nan'",
        ),
        Case(
            "gaze-q-current-unknown-joint",
            (*g, *TARGET, "--q-current", "neck=0.1"),
            "unknown joint 'neck'",
        ),
        Case(
            "gaze-q-current-mixed",
            (*g, *TARGET, "--q-current", "pan=0.1", "0.2"),
            "--q-current takes either NAME=VALUE pairs or one number per joint",
        ),
        Case(
            "gaze-q-current-named-out-of-limits",
            (*g, *TARGET, "--q-current", "pan=9"),
            "q_current: joint 'pan' reading 9 outside its limits",
        ),
        Case(
            "gaze-cameras-unknown",
            (*g, *TARGET, "--cameras", "camera_left_optical", "nope"),
            "nope",
        ),
        Case(
            "gaze-cameras-same",
            (*g, *TARGET, "--cameras", "camera_left_optical", "camera_left_optical"),
            "named twice",
        ),
        Case(
            "gaze-model-without-cameras",
            ("gaze", "{bad}", *TARGET),
            "camera_left_optical",
            lambda c: edit(
                c.model,
                lambda d: d.__setitem__(
                    "frames", [f for f in d["frames"] if f["kind"] != "camera"]
                ),
            ),
        ),
    ]
    return cases


HTML = ("--html", "{out}.html")


def _view() -> list[Case]:
    v = ("view", "iis_head", *HTML)
    cases = [
        c
        for c in robot_ref_faults("view-model", ("view", "{bad}", *HTML))
        if c.id.endswith(
            (
                "-missing",
                "-folder",
                "-binary",
                "-truncated",
                "-format",
                "-duplicate-key",
                "-deep",
                "-nan",
                "-unknown-parent",
                "-no-such-robot",
            )
        )
    ]
    cases += urdf_file_faults("view-urdf", ("view", "{bad}", *HTML))[:6]
    cases += [
        c
        for c in json_file_faults(
            "view-measurements",
            ("view", "iis_head", "--measurements", "{bad}", *HTML),
            lambda c: c.heldout,
            MEAS,
            None,
        )
        if c.id.endswith(("-missing", "-folder", "-binary", "-format", "-duplicate-key", "-deep"))
    ]
    cases += [
        Case(
            "view-nominal-missing",
            (*v, "--nominal", "{tmp}/nothere.urdf"),
            "{tmp}/nothere.urdf: no such file",
        ),
        Case(
            "view-nominal-not-xml",
            (*v, "--nominal", "{bad}"),
            "{bad}: not well-formed XML",
            lambda c: "<robot",
            name="bad.urdf",
        ),
        Case("view-target-nan", (*v, "--target", "1", "nan", "2"), "--target"),
        Case("view-target-text", (*v, "--target", "1", "2", "x"), "--target"),
        Case(
            "view-target-minus-nan",
            (*v, "--target", "-nan", "-1e-3", "2"),
            "--target X Y Z must be finite, got '-nan'",
        ),
        Case("view-q-unknown-joint", (*v, "--q", "neck=0.1"), "unknown joint 'neck'"),
        Case("view-q-count", (*v, "--q", "1", "2"), "needs 6 values"),
        Case("view-q-out-of-limits", (*v, "--q", "pan=4"), "pan"),
        Case("view-q-nan", (*v, "--q", "pan=nan"), "pan"),
        Case(
            "view-cameras-unknown",
            (*v, "--target", "-0.3", "-0.4", "0.66", "--cameras", "camera_left_optical", "eye"),
            "unknown frame 'eye'",
        ),
        Case(
            "view-policy-unknown",
            (*v, "--target", "-0.3", "-0.4", "0.66", "--policy", "stare"),
            "stare",
        ),
        Case(
            "view-screenshot-without-html",
            ("view", "iis_head", "--screenshot", "{out}.png"),
            "--screenshot needs --html",
        ),
        Case(
            "view-html-missing-folder",
            ("view", "iis_head", "--html", "{tmp}/no/v.html"),
            "folder {tmp}/no does not exist",
        ),
        Case(
            "view-html-is-folder",
            ("view", "iis_head", "--html", "{bad}"),
            "{bad}: is a folder",
            lambda c: Folder,
            name="out",
        ),
        Case(
            "view-package-path-missing",
            (*v, "--package-path", "{tmp}/nodir"),
            "{tmp}/nodir: no such folder",
        ),
        Case(
            "view-measurements-unknown-frame",
            (*v, "--measurements", "{bad}"),
            "plate_middle",
            lambda c: edit(
                c.heldout,
                lambda x: [
                    r["poses"].__setitem__("plate_middle", r["poses"].pop("plate_left"))
                    for r in x["records"]
                ],
            ),
        ),
    ]
    return cases


def _demo() -> list[Case]:
    return [
        Case(
            "demo-output-is-file",
            ("demo", "-o", "{bad}"),
            "{bad}",
            lambda c: "a file\n",
            name="out",
        ),
        Case(
            "demo-output-under-file",
            ("demo", "-o", "{bad}/sub"),
            "{bad}/sub",
            lambda c: "a file\n",
            name="out",
        ),
        Case("demo-seed-text", ("demo", "-o", "{out}", "--seed", "zero"), "--seed"),
        Case("demo-seed-negative", ("demo", "-o", "{out}", "--seed", "-1"), "--seed"),
        Case("demo-seed-float", ("demo", "-o", "{out}", "--seed", "1.5"), "--seed"),
        Case("demo-unknown-option", ("demo", "-o", "{out}", "--fast"), "--fast"),
    ]


def _study() -> list[Case]:
    return [
        Case("study-unknown", ("study", "fig12"), "invalid choice: 'fig12'"),
        Case("study-none", ("study",), "WHICH"),
        Case("study-unknown-option", ("study", "fig11", "--bogus"), "--bogus"),
        Case("study-fig11-M-one", ("study", "fig11", "--M", "1", "--out", "{out}"), "M >= 2"),
        Case(
            "study-fig11-trials-negative",
            ("study", "fig11", "--trials", "-3", "--out", "{out}"),
            "--trials",
        ),
        Case(
            "study-fig11-sigmas-text",
            ("study", "fig11", "--sigmas", "abc", "--out", "{out}"),
            "--sigmas",
        ),
        Case(
            "study-fig11-robot-unknown",
            ("study", "fig11", "--robot", "no_such_robot", "--out", "{out}"),
            "no_such_robot",
        ),
        Case(
            "study-crb-trials-one", ("study", "crb", "--trials", "1", "--out", "{out}"), "--trials"
        ),
        Case(
            "study-crb-sigma-negative",
            ("study", "crb", "--sigma-mm", "-1", "--out", "{out}"),
            "sigma",
        ),
        Case(
            "study-crb-robot-missing",
            ("study", "crb", "--robot", "{tmp}/nope.json", "--out", "{out}"),
            "{tmp}/nope.json",
        ),
        Case(
            "study-crb-robot-no-plate",
            ("study", "crb", "--robot", "{bad}", "--trials", "2", "--out", "{out}"),
            "no frame of kind 'plate'",
            lambda c: NO_PLATE_URDF,
            name="arm.urdf",
        ),
        Case(
            "study-stereo-samples-zero",
            ("study", "stereo", "--samples", "0", "--out", "{out}"),
            "--samples",
        ),
        Case(
            "study-li2010-repeats-zero",
            ("study", "li2010", "--repeats", "0", "--out", "{out}"),
            "--repeats",
        ),
        Case(
            "study-li2010-max-poses-one",
            ("study", "li2010", "--max-poses", "1", "--out", "{out}"),
            "--max-poses",
        ),
        Case("study-stage2-poses-one", ("study", "stage2", "--poses", "1"), "--poses"),
        Case("study-kinhec-no-dataset", ("study", "kinhec", "{tmp}/nothing"), "kinhec"),
        Case(
            "study-stage2-noise-nan",
            (
                "study",
                "stage2",
                "--noise",
                "nan",
                "--poses",
                "3",
                "--seeds",
                "1",
                "--methods",
                "tsai",
            ),
            "--noise",
        ),
        Case(
            "study-stage2-method-unknown",
            ("study", "stage2", "--methods", "magic", "--poses", "3", "--seeds", "1"),
            "magic",
        ),
        Case(
            "study-images-poses-zero",
            ("study", "images", "--poses", "0", "--out", "{out}"),
            "--poses",
        ),
        Case(
            "study-gate-trials-negative",
            ("study", "gate", "--trials", "-1", "--out", "{out}"),
            "trial counts",
        ),
    ]


def _bench() -> list[Case]:
    return [
        Case("bench-unknown", ("bench", "ik"), "invalid choice: 'ik'"),
        Case("bench-unknown-option", ("bench", "fk", "--bogus"), "--bogus"),
        Case(
            "bench-fk-configurations-zero",
            ("bench", "fk", "--configurations", "0"),
            "--configurations",
        ),
        Case(
            "bench-fk-configurations-text",
            ("bench", "fk", "--configurations", "nan"),
            "--configurations",
        ),
        Case("bench-fk-repeat-zero", ("bench", "fk", "--repeat", "0"), "--repeat"),
        Case(
            "bench-fk-model-unknown", ("bench", "fk", "--model", "no_such_robot"), "no_such_robot"
        ),
        Case(
            "bench-fk-model-folder",
            ("bench", "fk", "--model", "{bad}"),
            "{bad}: is a folder",
            lambda c: Folder,
        ),
        Case(
            "bench-fk-model-not-json",
            ("bench", "fk", "--model", "{bad}"),
            "{bad}: not valid JSON",
            lambda c: "{]",
        ),
        Case("bench-gaze-targets-zero", ("bench", "gaze", "--targets", "0"), "--targets"),
        Case("bench-gaze-targets-negative", ("bench", "gaze", "--targets", "-4"), "--targets"),
        Case(
            "bench-gaze-json-missing-folder",
            ("bench", "gaze", "--targets", "1", "--json", "{tmp}/no/b.json"),
            "folder {tmp}/no does not exist",
        ),
    ]


def _plan() -> list[Case]:
    p = ("plan", "iis_head", "-o", OUT_JSON)
    return [
        Case("plan-n-zero", (*p, "--n", "0"), "--n must be at least 1"),
        Case("plan-n-negative", (*p, "--n", "-3"), "--n"),
        Case("plan-n-or-target-error", p, "--n --target-error"),
        Case("plan-target-error-negative", (*p, "--target-error", "-1"), "--target-error"),
        Case("plan-target-error-nan", (*p, "--target-error", "nan"), "--target-error"),
        Case("plan-sigma-negative", (*p, "--n", "5", "--sigma-mm", "-1"), "--sigma-mm"),
        Case(
            "plan-robot-unknown",
            ("plan", "no_such_robot", "-o", OUT_JSON, "--n", "5"),
            "no_such_robot",
        ),
        Case(
            "plan-output-missing-folder",
            ("plan", "iis_head", "-o", "{tmp}/no/p.json", "--n", "5"),
            "folder {tmp}/no does not exist",
        ),
        Case(
            "plan-rig-missing",
            (*p, "--n", "5", "--rig", "{tmp}/nope.yaml"),
            "{tmp}/nope.yaml: no such file",
        ),
        Case(
            "plan-rig-not-yaml",
            (*p, "--n", "5", "--rig", "{bad}"),
            "{bad}",
            lambda c: "K1: [1, 2\n",
            name="rig.yaml",
        ),
        Case(
            "plan-task-region-missing",
            (*p, "--n", "5", "--task-region", "{tmp}/nope.csv"),
            "{tmp}/nope.csv: no such file",
        ),
        Case("plan-measured-unknown", (*p, "--n", "5", "--measured", "nose"), "nose"),
        Case("plan-range-unknown-joint", (*p, "--n", "5", "--range", "neck=0:1"), "neck"),
    ]


def _reach() -> list[Case]:
    r = ("reach", "iis_head", "-o", "{out}.png")
    return [
        Case(
            "reach-range-inverted",
            (*r, "--range", "3", "0.2"),
            "range must be two finite distances",
        ),
        Case("reach-range-negative", (*r, "--range", "-1", "2"), "range"),
        Case("reach-range-nan", (*r, "--range", "nan", "2"), "range"),
        Case("reach-samples-zero", (*r, "--samples", "0", "3", "3"), "samples"),
        Case("reach-camera-unknown", (*r, "--camera", "nope"), "unknown frame 'nope'"),
        Case("reach-grid-unknown", (*r, "--grid", "cube"), "invalid choice: 'cube'"),
        Case(
            "reach-output-missing-folder",
            ("reach", "iis_head", "-o", "{tmp}/no/r.png"),
            "folder {tmp}/no does not exist",
        ),
        Case(
            "reach-json-missing-folder",
            (*r, "--json", "{tmp}/no/r.json", "--samples", "2", "2", "2"),
            "folder {tmp}/no does not exist",
        ),
        Case("reach-robot-unknown", ("reach", "no_such_robot", "-o", "{out}.png"), "no_such_robot"),
        Case(
            "reach-output-folder-is-a-file",
            ("reach", "iis_head", "-o", "{bad}/r.png"),
            "folder {bad} is a file, not a folder",
            lambda c: "not a folder",
            name="afile",
        ),
        Case(
            "reach-urdf-not-xml",
            ("reach", "{bad}", "-o", "{out}.png"),
            "{bad}: not well-formed XML",
            lambda c: "<robot",
            name="bad.urdf",
        ),
    ]


def _calibrate() -> list[Case]:
    board = {"format": "cpc2urdf/board@1"}
    b = ("calibrate", "camera", "{images}/left", "--board", "{bad}", "-o", "{out}.yaml")
    return [
        Case("calibrate-board-missing", b, "{bad}: no such file", lambda c: Missing),
        Case("calibrate-board-folder", b, "{bad}: is a folder", lambda c: Folder),
        Case("calibrate-board-binary", b, "{bad}: is a binary file", lambda c: PNG),
        Case("calibrate-board-not-json", b, "{bad}: not valid JSON", lambda c: "{\n"),
        Case("calibrate-board-deep", b, "{bad}: nested more than 64 levels deep", lambda c: DEEP),
        Case(
            "calibrate-board-duplicate-key",
            b,
            "{bad}: duplicate key 'format'",
            lambda c: with_duplicate_key(board),
        ),
        Case(
            "calibrate-board-format",
            b,
            "{bad}: format is 'something/else@1'",
            lambda c: {"format": "something/else@1"},
        ),
        Case("calibrate-board-no-kind", b, "{bad}: kind must be one of", lambda c: board),
        Case(
            "calibrate-mode-unknown",
            ("calibrate", "stereo", "{images}", "--board", "{bad}", "-o", "{out}.yaml"),
            "invalid choice: 'stereo'",
            lambda c: board,
        ),
        Case(
            "calibrate-units-unknown",
            (*b, "--units", "km"),
            "invalid choice: 'km'",
            lambda c: board,
        ),
        Case(
            "calibrate-no-board",
            ("calibrate", "camera", "{images}/left", "-o", "{out}.yaml"),
            "--board",
        ),
    ]


def _bag() -> list[Case]:
    pose = ("--pose", "plate_left=/plate_left")
    b = ("bag", "{bad}", "-o", OUT_JSON, *pose)
    garbage = lambda c: b"not a bag"  # noqa: E731
    return [
        Case("bag-missing", b, "{bad}: no such bag", lambda c: Missing, name="rec.bag"),
        Case("bag-not-a-bag", b, "{bad}: not a readable ROS bag", garbage, name="rec.bag"),
        Case(
            "bag-empty-folder",
            b,
            "{bad}: a folder without metadata.yaml is not a rosbag2 bag",
            lambda c: Folder,
            name="rec2",
        ),
        Case(
            "bag-neither-pose-nor-image",
            ("bag", "{bad}", "-o", OUT_JSON),
            "give --pose",
            garbage,
            name="rec.bag",
        ),
        Case(
            "bag-pose-and-image", (*b, "--image", "left=/left"), "not both", garbage, name="rec.bag"
        ),
        Case(
            "bag-pose-syntax",
            ("bag", "{bad}", "-o", OUT_JSON, "--pose", "plate_left"),
            "--pose expects FRAME=TOPIC",
            garbage,
            name="rec.bag",
        ),
        Case(
            "bag-pose-unknown-frame",
            ("bag", "{bad}", "-o", OUT_JSON, "--pose", "nose=/p"),
            "--pose nose: unknown frame",
            garbage,
            name="rec.bag",
        ),
        Case(
            "bag-sync-negative",
            (*b, "--sync-tolerance", "-1"),
            "sync_tolerance",
            garbage,
            name="rec.bag",
        ),
        Case(
            "bag-rest-window-nan",
            (*b, "--rest-window", "nan"),
            "rest_window",
            garbage,
            name="rec.bag",
        ),
        Case(
            "bag-output-missing-folder",
            ("bag", "{bad}", "-o", "{tmp}/no/m.json", *pose),
            "folder {tmp}/no does not exist",
            garbage,
            name="rec.bag",
        ),
        Case(
            "bag-robot-unknown",
            (*b, "--robot", "no_such_robot"),
            "no_such_robot",
            garbage,
            name="rec.bag",
        ),
    ]


def _top() -> list[Case]:
    return [
        Case("top-unknown-command", ("frobnicate", "x"), "invalid choice: 'frobnicate'"),
    ]


def all_cases() -> list[Case]:
    cases = [
        *_demo(),
        *_export(),
        *_check(),
        *_bench(),
        *_study(),
        *_simulate(),
        *_measure(),
        *_identify(),
        *_accuracy(),
        *_handeye(),
        *_view(),
        *_gaze(),
        *_plan(),
        *_reach(),
        *_calibrate(),
        *_bag(),
        *_top(),
    ]
    ids = [c.id for c in cases]
    dup = {i for i in ids if ids.count(i) > 1}
    assert not dup, f"duplicate case ids: {sorted(dup)}"
    return cases


CASES = all_cases()
