"""One URDF validator behind register_robot: every malformed description a RobotDescriptionError that
names the element, before anything is built from it."""

from __future__ import annotations

import pytest
import torch
from test_user_robot import URDF

import kinlearn
from kinlearn.body.robot import register_robot, unregister_robot
from kinlearn.errors import ConfigError, DTypeError, RobotDescriptionError, UnknownRobotError

ELBOW = '<limit lower="-2.2" upper="2.2" velocity="2.5" effort="10"/>'


def _with(old: str, new: str) -> str:
    assert URDF.count(old) == 1, old
    return URDF.replace(old, new)


BROKEN = {
    "not a tree": (_with('<child link="l4"/>', '<child link="l3"/>'), r"child of two joints.*line \d+"),
    "duplicate link": (_with('<link name="l4"/>', '<link name="l3"/>'), "two links are named 'l3'"),
    "duplicate joint": (_with('joint name="wrist"', 'joint name="elbow"'), "two joints are named 'elbow'"),
    "undeclared child": (_with('<link name="tool"/>', ""), "'tool', which the URDF does not declare"),
    "lower > upper": (_with(ELBOW, '<limit lower="2.2" upper="-2.2" velocity="2.5"/>'), "lower < upper"),
    "lower nan": (
        _with(ELBOW, '<limit lower="nan" upper="2.2" velocity="2.5"/>'),
        "elbow's limits must be finite",
    ),
    "upper inf": (
        _with(ELBOW, '<limit lower="-2.2" upper="inf" velocity="2.5"/>'),
        "elbow's limits must be finite",
    ),
    "limit not a number": (
        _with(ELBOW, '<limit lower="-2.2" upper="two" velocity="2.5"/>'),
        "upper must be a number",
    ),
    "velocity not a number": (_with(ELBOW, '<limit lower="-2.2" upper="2.2" velocity="fast"/>'), "velocity"),
    "negative velocity": (
        _with(ELBOW, '<limit lower="-2.2" upper="2.2" velocity="-1"/>'),
        "velocity limit must be > 0",
    ),
    "origin nan": (_with('<origin xyz="0 0 0.25"/>', '<origin xyz="0 nan 0.25"/>'), "joint elbow origin xyz"),
    "origin not numbers": (
        _with('<origin xyz="0 0 0.25"/>', '<origin xyz="0 zero 0.25"/>'),
        "3 finite numbers",
    ),
    "xacro": (_with('<origin xyz="0 0 0.25"/>', '<origin xyz="0 0 ${l2}"/>'), r"unexpanded xacro.*\$\{l2\}"),
    "no parent": (_with('<parent link="l2"/>', ""), "joint 'elbow'.*has no <parent link"),
    "no child": (_with('<child link="l3"/>', ""), "joint 'elbow'.*has no <child link"),
    "two roots": (
        _with(
            '<joint name="flange" type="fixed"><parent link="l4"/><child link="tool"/>'
            '<origin xyz="0 0 0.10"/></joint>',
            "",
        ),
        "one root link; this one has 2",
    ),
    "not a robot": (
        URDF.replace("<robot", "<robt").replace("</robot>", "</robt>"),
        "root element is <robot>",
    ),
}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_a_malformed_urdf_is_refused_naming_its_element(tmp_path, case):
    text, match = BROKEN[case]
    path = tmp_path / "arm.urdf"
    path.write_text(text)
    with pytest.raises(RobotDescriptionError, match=match):
        register_robot("arm", path, "tool" if case != "undeclared child" else "l4")
    assert "arm" not in kinlearn.available_robots()


def test_the_line_is_named(tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(BROKEN["duplicate joint"][0])
    with pytest.raises(RobotDescriptionError) as info:
        register_robot("arm", path, "tool")
    line = next(
        i for i, row in enumerate(BROKEN["duplicate joint"][0].splitlines(), 1) if 'name="elbow"' in row
    )
    assert f"line {line}" in str(info.value)


@pytest.mark.parametrize("name", ["a/b", "../iiwa14", "x/../iiwa14", "arm name", "", "-arm", "arm.urdf"])
def test_a_robot_name_is_a_word(tmp_path, name):
    path = tmp_path / "arm.urdf"
    path.write_text(URDF)
    with pytest.raises(ConfigError, match="robot name"):
        register_robot(name, path, "tool")


def test_homes_and_regions_of_strings_are_typed(tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(URDF)
    with pytest.raises(DTypeError, match="home"):
        register_robot("arm", path, "tool", home=["a", "b", "c", "d"])
    with pytest.raises(ConfigError, match="region"):
        register_robot("arm", path, "tool", region="somewhere")
    assert "arm" not in kinlearn.available_robots()


def test_a_registered_arm_never_plans_with_another_arms_planner(tmp_path):
    """A 7-joint copy of the iiwa14 under another name gets no shipped planner (not the iiwa14's)."""
    iiwa = kinlearn.load_robot("iiwa14")
    path = tmp_path / "copy.urdf"
    path.write_bytes(iiwa.urdf)
    robot = register_robot("iiwa-copy", path, iiwa.ee_frame)
    try:
        q = robot.sample(2, torch.Generator().manual_seed(0), dtype=torch.float64)
        with pytest.raises(ConfigError, match="ships no planner for 'iiwa-copy'"):
            kinlearn.plan(q[0], q[1], robot="iiwa-copy")
        with pytest.raises(ConfigError, match="ships no planner"):
            kinlearn.plan(q[0], q[1], robot=robot)
    finally:
        unregister_robot("iiwa-copy")


def test_a_sphere_urdf_goes_through_the_same_validator(tmp_path):
    path, spheres = tmp_path / "arm.urdf", tmp_path / "arm_spheres.urdf"
    path.write_text(URDF)
    spheres.write_text(BROKEN["duplicate link"][0])
    # refused where it is registered, by the same validator, naming the file
    with pytest.raises(RobotDescriptionError, match=r"the sphere URDF .*: two links are named 'l3'"):
        register_robot("arm", path, "tool", spheres=spheres)
    with pytest.raises(UnknownRobotError):  # nothing half-registered
        kinlearn.load_robot("arm")
