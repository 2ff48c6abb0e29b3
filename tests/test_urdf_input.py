"""``cpc2urdf.urdf.input``: the URDF rules checked before any parser sees a file, one problem per
line naming the element and its line; the URDFs we write always pass."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from cpc2urdf.errors import InputFileError
from cpc2urdf.files.robot_ref import load_model
from cpc2urdf.urdf.document import urdf_from_model
from cpc2urdf.urdf.input import URDF_MAX_DEPTH, read_urdf, urdf_problems, validate_urdf
from random_trees import random_tree

HEAD = urdf_from_model(load_model("iis_head"))


def _line_of(text: str, needle: str) -> int:
    return text[: text.index(needle)].count("\n") + 1


def _in_joint(name: str, old: str, new: str, text: str = HEAD) -> str:
    i = text.index(f'<joint name="{name}"')
    j = text.index("</joint>", i)
    assert old in text[i:j], (name, old)
    return text[:i] + text[i:j].replace(old, new, 1) + text[j:]


def _only(text: str) -> str:
    problems = urdf_problems(text)
    assert len(problems) == 1, problems
    return problems[0]


def test_the_urdfs_we_write_pass() -> None:
    assert urdf_problems(HEAD) == []
    rng = np.random.default_rng(0)
    for _ in range(20):
        assert urdf_problems(urdf_from_model(random_tree(rng))) == []


def test_not_xml_empty_and_the_wrong_root() -> None:
    assert urdf_problems("not xml") == ["not well-formed XML (syntax error: line 1, column 0)"]
    assert urdf_problems("  \n") == ["is empty, expected a URDF file"]
    truncated = urdf_problems(HEAD[: len(HEAD) // 2])
    assert len(truncated) == 1 and re.fullmatch(
        r"not well-formed XML \(\w[\w ]*: line \d+, column \d+\)", truncated[0]
    )
    assert urdf_problems('<robot name="r">') == [
        "not well-formed XML (no element found: line 1, column 16)"
    ]
    assert urdf_problems('<sdf><link name="a"/></sdf>') == [
        "the root element is <sdf>, expected <robot> (line 1)"
    ]
    assert urdf_problems('<robot><link name="a"/></robot>') == [
        "<robot> has no name attribute (line 1)"
    ]
    assert urdf_problems('<robot name="r"/>') == ["<robot> has no <link> (line 1)"]
    assert urdf_problems('<robot name="r" version="2.0"><link name="a"/></robot>') == [
        "<robot> version '2.0' is not 1.0 (line 1)"
    ]


def test_what_parsers_read_differently_is_refused() -> None:
    entity = '<!DOCTYPE robot [<!ENTITY x "0.5">]>\n<robot name="r"><link name="&x;"/></robot>'
    assert urdf_problems(entity) == ["declares the XML entity 'x' (line 1); URDF files use none"]
    latin = '<?xml version="1.0" encoding="ISO-8859-1"?><robot name="r"><link name="a"/></robot>'
    assert urdf_problems(latin) == ["declares encoding 'ISO-8859-1'; URDF files are read as UTF-8"]
    pi = (
        '<?xml version="1.0"?>\n<?xml-stylesheet href="a"?><robot name="r"><link name="a"/></robot>'
    )
    assert urdf_problems(pi) == [
        "has the processing instruction <?xml-stylesheet ...?> (line 2); URDF files use none"
    ]
    deep = f'<robot name="r"><link name="a"/><gazebo>{"<a>" * 100000}{"</a>" * 100000}</gazebo></robot>'
    assert urdf_problems(deep) == [f"elements nested more than {URDF_MAX_DEPTH} deep (line 1)"]
    ok = '<?xml version="1.0" encoding="utf-8"?>\n<!DOCTYPE robot>\n<!-- c --><robot name="r"><link name="a"/></robot>'
    assert urdf_problems(ok) == []


@pytest.mark.parametrize(
    "value, problem",
    [
        ("nan 0 0", "is not finite"),
        ("0 -inf 0", "is not finite"),
        ("0 0 Infinity", "is not finite"),
        ("1e999 0 0", "is not finite"),
        ("0 0", "is not 3 numbers"),
        ("0 0 0 0", "is not 3 numbers"),
        ("0,0,0", "is not 3 numbers"),
        ("0x1 0 0", "is not 3 numbers"),
        ("1_0 0 0", "is not 3 numbers"),
        ("${a} 0 0", "is not 3 numbers (an unexpanded xacro expression? run xacro first)"),
    ],
)
def test_numbers_are_decimal_finite_and_counted(value: str, problem: str) -> None:
    text = _in_joint("pan", '<origin xyz="', f'<origin xyz="{value}" old="')
    line = _line_of(text, f'<origin xyz="{value}"')
    assert _only(text) == f"joint 'pan': origin xyz {value!r} {problem} (line {line})"


def test_numbers_everywhere_name_their_element() -> None:
    vis = HEAD.index('<visual name="table_x_axis">')
    origin = HEAD.index('<origin xyz="0 0 0"', vis)
    text = HEAD[:origin] + '<origin xyz="nan 0 0"' + HEAD[origin + len('<origin xyz="0 0 0"') :]
    assert (
        _only(text)
        == f"link 'table_x_link': visual 'table_x_axis' origin xyz 'nan 0 0' is not finite (line {_line_of(text, 'nan 0 0')})"
    )
    inertial = '<inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="inf" iyz="0" izz="1"/></inertial>'
    text = HEAD.replace('<link name="base">', f'<link name="base">{inertial}')
    assert _only(text).startswith("link 'base': inertial inertia iyy 'inf' is not finite")
    text = re.sub(
        r'(<joint name="tilt".*?<limit[^>]*?) upper="[^"]*"',
        r'\1 upper="1e400"',
        HEAD,
        count=1,
        flags=re.S,
    )
    assert _only(text).startswith("joint 'tilt': limit upper '1e400' is not finite")
    text = HEAD.replace('rgba="0.55 0.55 0.55 1.0"', 'rgba="0.55 0.55 nan 1.0"')
    assert _only(text).startswith(
        "material 'cpc2urdf_base': color rgba '0.55 0.55 nan 1.0' is not finite"
    )
    text = HEAD.replace('<box size="0.12 0.12 0.01"/>', '<box size="0.12 NaN 0.01"/>')
    assert _only(text).startswith(
        "link 'base': visual 'base_plate' geometry box size '0.12 NaN 0.01' is not finite"
    )
    text = HEAD.replace('<box size="0.12 0.12 0.01"/>', '<cylinder radius="nan" length="1"/>')
    assert _only(text).startswith(
        "link 'base': visual 'base_plate' geometry cylinder radius 'nan' is not finite"
    )


def test_joints_name_existing_links_and_form_one_tree() -> None:
    text = HEAD.replace('<parent link="table_x_link"/>', '<parent link="nope"/>')
    assert (
        _only(text)
        == f"joint 'table_y': parent link 'nope' is not a link of this URDF (line {_line_of(text, 'nope')})"
    )
    text = HEAD.replace('<child link="pan_link"/>', '<child link="nope"/>')
    assert _only(text).startswith("joint 'pan': child link 'nope' is not a link of this URDF")
    extra = '<joint name="j2" type="fixed"><parent link="world"/><child link="pan_link"/></joint>'
    assert _only(HEAD.replace("</robot>", extra + "</robot>")).startswith(
        "joint 'j2': link 'pan_link' is already the child of joint 'pan'; a link has one parent"
    )
    assert _only(HEAD.replace("</robot>", '<link name="lonely"/></robot>')).startswith(
        "links 'world', 'lonely' are all roots (the child of no joint); a URDF is one tree"
    )
    back = '<joint name="back" type="fixed"><parent link="pan_link"/><child link="world"/></joint>'
    assert "form a cycle; a URDF is a tree" in _only(HEAD.replace("</robot>", back + "</robot>"))
    self_loop = '<joint name="s" type="fixed"><parent link="base"/><child link="base"/></joint>'
    assert (
        "joint 's': parent and child are the same link 'base'"
        in urdf_problems(HEAD.replace("</robot>", self_loop + "</robot>"))[0]
    )
    assert _only(
        HEAD.replace('<link name="world"/>', '<link name="world"/><link name="world"/>')
    ).startswith("link 'world' is defined twice (lines")


@pytest.mark.parametrize(
    "old, new, problem",
    [
        ('type="revolute"', "", "joint 'pan' has no type attribute"),
        ('type="revolute"', 'type="hinge"', "joint 'pan': type 'hinge' is not a URDF joint type"),
        ('<parent link="table_y_link"/>', "", "joint 'pan' has no <parent link=...>"),
        ("<limit ", "<limits ", "joint 'pan' is revolute but has no <limit>"),
        ('effort="', 'x="', "joint 'pan': limit has no effort attribute"),
        ('velocity="', 'velocity="-', "joint 'pan': limit velocity '-"),
        ('<axis xyz="', '<axis xyz="0 0 0" x="', "joint 'pan': axis xyz '0 0 0' is zero"),
        (
            "<limit ",
            '<mimic joint="nope"/><limit ',
            "joint 'pan': mimic joint 'nope' is not a joint of this URDF",
        ),
    ],
)
def test_joint_elements(old: str, new: str, problem: str) -> None:
    assert _only(_in_joint("pan", old, new)).startswith(problem)


@pytest.mark.parametrize(
    "shape, problem",
    [
        ("", "visual 'base_plate' geometry has no shape (box, cylinder, sphere or mesh)"),
        (
            '<capsule radius="1" length="1"/>',
            "visual 'base_plate' geometry <capsule> is not a URDF shape",
        ),
        ('<mesh scale="1 1 1"/>', "visual 'base_plate' geometry mesh has no filename attribute"),
        (
            '<mesh filename="a.stl" scale="1"/>',
            "visual 'base_plate' geometry mesh scale '1' is not 3 numbers",
        ),
        ('<cylinder radius="1"/>', "visual 'base_plate' geometry cylinder has no length attribute"),
    ],
)
def test_geometry(shape: str, problem: str) -> None:
    assert _only(HEAD.replace('<box size="0.12 0.12 0.01"/>', shape)).startswith(
        f"link 'base': {problem}"
    )


def test_inertials_and_materials() -> None:
    no_mass = '<inertial><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>'
    assert _only(HEAD.replace('<link name="base">', f'<link name="base">{no_mass}')).startswith(
        "link 'base': inertial has no <mass value>"
    )
    no_izz = (
        '<inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0"/></inertial>'
    )
    assert _only(HEAD.replace('<link name="base">', f'<link name="base">{no_izz}')).startswith(
        "link 'base': inertial has no <inertia> izz"
    )
    bare = HEAD.replace(
        '<material name="cpc2urdf_base"><color rgba="0.55 0.55 0.55 1.0"/></material>',
        '<material name="cpc2urdf_base"/>',
    )
    assert _only(bare).startswith(
        "material 'cpc2urdf_base' has no <color rgba> and no <texture filename>"
    )
    assert _only(
        HEAD.replace('<material name="cpc2urdf_head">', '<material name="cpc2urdf_base">')
    ).startswith("material 'cpc2urdf_base' is defined twice")


def test_what_no_parser_reads_is_left_alone() -> None:
    gazebo = (
        '<gazebo reference="base"><sensor><pose>nan nan</pose><origin xyz="x"/></sensor></gazebo>'
    )
    assert urdf_problems(HEAD.replace("</robot>", gazebo + "</robot>")) == []
    assert urdf_problems(HEAD.replace('<link name="base">', f'<link name="base">{gazebo}')) == []
    spaced = _in_joint("pan", '<origin xyz="', '<origin xyz=" 0  0 0 " old="')
    assert urdf_problems(spaced) == []
    assert (
        urdf_problems(_in_joint("pan", '<origin xyz="', '<origin xyz="+.5 -0. 1E-3" old="')) == []
    )


def test_validate_and_read_name_the_source_and_count_the_rest(tmp_path: Path) -> None:
    two = HEAD.replace('<parent link="table_x_link"/>', '<parent link="a"/>').replace(
        '<child link="pan_link"/>', '<child link="b"/>'
    )
    with pytest.raises(
        InputFileError,
        match=r"^<text>: joint 'table_y': parent link 'a' .* \(and 1 more problem\)$",
    ):
        validate_urdf(two, "<text>")
    p = tmp_path / "h.urdf"
    p.write_bytes(b"\xef\xbb\xbf" + HEAD.encode())  # a BOM is fine
    assert read_urdf(p) == HEAD
    with pytest.raises(InputFileError, match="is a folder, expected a URDF file"):
        read_urdf(tmp_path)
    p.write_text("nan")
    with pytest.raises(InputFileError, match=rf"^{re.escape(str(p))}: not well-formed XML"):
        read_urdf(p)
