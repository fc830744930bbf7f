"""URDF descriptions of a UR10 and a Franka Panda for the tests, written from the public
description values (ur_description's UR10 kinematics: d1 = 0.1273, a2 = -0.612,
a3 = -0.5723, d4 = 0.163941, d5 = 0.1157, d6 = 0.0922; franka_description's joint
origins), with meshes and inertias so that a writer can be seen to keep them."""

from __future__ import annotations

from pathlib import Path

PI = "3.141592653589793"
HALF = "1.5707963267948966"


def _link(name: str, mass: float | None = None, com: str = "0 0 0", mesh: str | None = None) -> str:
    parts = [f'  <link name="{name}">']
    if mesh:
        parts.append(f'    <visual><geometry><mesh filename="{mesh}"/></geometry></visual>')
    if mass is not None:
        parts.append(f'    <inertial><origin xyz="{com}" rpy="0 0 0"/><mass value="{mass}"/>'
                     '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>'
                     '</inertial>')
    parts.append("  </link>")
    return "\n".join(parts)


def _joint(name, kind, parent, child, xyz="0 0 0", rpy="0 0 0", axis="0 0 1",
           limits=None) -> str:
    text = (f'  <joint name="{name}" type="{kind}">\n    <parent link="{parent}"/>'
            f'<child link="{child}"/>\n    <origin xyz="{xyz}" rpy="{rpy}"/>')
    if kind != "fixed":
        text += f'\n    <axis xyz="{axis}"/>'
    if limits:
        text += (f'\n    <limit lower="{limits[0]}" upper="{limits[1]}" effort="150" '
                 'velocity="2.1"/>')
    return text + "\n  </joint>"


def ur10_urdf() -> str:
    """UR10 as ur_description lays it out: base_link, base_link_inertia (turned half a
    turn), six joints whose origins are the driver's kinematics values, flange and tool0,
    and the ROS-Industrial ``base`` frame (a second leaf)."""
    mesh = "package://ur_description/meshes/ur10/visual/{}.dae"
    two_pi = ("-6.283185307179586", "6.283185307179586")
    lines = ['<?xml version="1.0"?>', '<robot name="ur10">', "  <!-- UR10, test copy -->",
             _link("base_link"), _link("base_link_inertia", 4.0, mesh=mesh.format("base")),
             _link("shoulder_link", 7.778, "0 0.00193 -0.02561", mesh.format("shoulder")),
             _link("upper_arm_link", 12.93, "-0.306 0 0.175", mesh.format("upperarm")),
             _link("forearm_link", 3.87, "-0.2855 0 0.04", mesh.format("forearm")),
             _link("wrist_1_link", 1.96, "0 -0.0016 -0.0082", mesh.format("wrist1")),
             _link("wrist_2_link", 1.96, "0 0.0016 -0.0082", mesh.format("wrist2")),
             _link("wrist_3_link", 0.202, "0 0 -0.0193", mesh.format("wrist3")),
             _link("base"), _link("flange"), _link("tool0"),
             _joint("base_link-base_link_inertia", "fixed", "base_link", "base_link_inertia",
                    rpy=f"0 0 {PI}"),
             _joint("shoulder_pan_joint", "revolute", "base_link_inertia", "shoulder_link",
                    xyz="0 0 0.1273", limits=two_pi),
             _joint("shoulder_lift_joint", "revolute", "shoulder_link", "upper_arm_link",
                    rpy=f"{HALF} 0 0", limits=two_pi),
             _joint("elbow_joint", "revolute", "upper_arm_link", "forearm_link",
                    xyz="-0.612 0 0", limits=two_pi),
             _joint("wrist_1_joint", "revolute", "forearm_link", "wrist_1_link",
                    xyz="-0.5723 0 0.163941", limits=two_pi),
             _joint("wrist_2_joint", "revolute", "wrist_1_link", "wrist_2_link",
                    xyz="0 -0.1157 -2.373046667922381e-11", rpy=f"{HALF} 0 0", limits=two_pi),
             _joint("wrist_3_joint", "revolute", "wrist_2_link", "wrist_3_link",
                    xyz="0 0.0922 -1.891053610174209e-11", rpy=f"1.570796326589793 {PI} {PI}",
                    limits=two_pi),
             _joint("base_link-base_fixed_joint", "fixed", "base_link", "base", rpy=f"0 0 {PI}"),
             _joint("wrist_3-flange", "fixed", "wrist_3_link", "flange",
                    rpy=f"0 -{HALF} -{HALF}"),
             _joint("flange-tool0", "fixed", "flange", "tool0", rpy=f"{HALF} 0 {HALF}"),
             "</robot>"]
    return "\n".join(lines) + "\n"


def panda_urdf() -> str:
    """Franka Panda arm and hand as franka_description lays them out (link0 .. link8,
    hand, two fingers: a branching tree whose chain needs a tip_link)."""
    mesh = "package://franka_description/meshes/visual/{}.dae"
    masses = (4.97, 0.65, 3.23, 3.59, 1.23, 1.67, 0.74)
    coms = ("0.003 -0.002 -0.175", "-0.003 -0.028 0.003", "0.027 0.039 -0.066",
            "-0.053 0.104 0.027", "-0.011 0.042 -0.128", "0.06 -0.014 -0.01", "0.01 -0.004 0.06")
    origins = (("0 0 0.333", "0 0 0"), ("0 0 0", f"-{HALF} 0 0"), ("0 -0.316 0", f"{HALF} 0 0"),
               ("0.0825 0 0", f"{HALF} 0 0"), ("-0.0825 0.384 0", f"-{HALF} 0 0"),
               ("0 0 0", f"{HALF} 0 0"), ("0.088 0 0", f"{HALF} 0 0"))
    limits = (("-2.8973", "2.8973"), ("-1.7628", "1.7628"), ("-2.8973", "2.8973"),
              ("-3.0718", "-0.0698"), ("-2.8973", "2.8973"), ("-0.0175", "3.7525"),
              ("-2.8973", "2.8973"))
    lines = ['<?xml version="1.0" ?>', '<robot name="panda">',
             _link("panda_link0", 2.92, "-0.025 0 0.03", mesh.format("link0"))]
    for i in range(1, 8):
        lines.append(_link(f"panda_link{i}", masses[i - 1], coms[i - 1],
                           mesh.format(f"link{i}")))
    lines += [_link("panda_link8"), _link("panda_hand", 0.73, "0 0 0.04", mesh.format("hand")),
              _link("panda_leftfinger", 0.015, "0 0.01 0.02", mesh.format("finger")),
              _link("panda_rightfinger", 0.015, "0 -0.01 0.02", mesh.format("finger"))]
    for i in range(1, 8):
        xyz, rpy = origins[i - 1]
        lines.append(_joint(f"panda_joint{i}", "revolute", f"panda_link{i - 1}",
                            f"panda_link{i}", xyz, rpy, limits=limits[i - 1]))
    lines += [_joint("panda_joint8", "fixed", "panda_link7", "panda_link8", xyz="0 0 0.107"),
              _joint("panda_hand_joint", "fixed", "panda_link8", "panda_hand",
                     rpy="0 0 -0.7853981633974483"),
              _joint("panda_finger_joint1", "prismatic", "panda_hand", "panda_leftfinger",
                     xyz="0 0 0.0584", axis="0 1 0", limits=("0.0", "0.04")),
              _joint("panda_finger_joint2", "prismatic", "panda_hand", "panda_rightfinger",
                     xyz="0 0 0.0584", axis="0 -1 0", limits=("0.0", "0.04")),
              "</robot>"]
    return "\n".join(lines) + "\n"


def write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text)
    return path
