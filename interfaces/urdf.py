"""The URDF a station loads: the robot's, with the datasheet's joint limits and its tool.

The twin (PyBullet) and the controller (Pinocchio) load the same file, so their joints, limits,
links and TCP agree by construction. :func:`station_urdf` starts from the robot's URDF
(:func:`interfaces.robots.resolve_urdf`), makes every mesh path absolute (``package://`` URIs
and paths relative to the URDF), writes the datasheet's position and velocity limits into the
arm's joints, and, for a tool mounted on the flange, replaces whatever the URDF hangs below the
robot's flange link (a hand it ships with) by the tool's links (:func:`tool_elements`). The
result is written once per content under ``<cache>/urdf/``.
"""

from __future__ import annotations

import hashlib
import math
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from interfaces.cache import cache_root
from interfaces.errors import ConfigError
from interfaces.fileio import write_atomic
from interfaces.robots import RobotSpec, package_root, resolve_urdf
from interfaces.tools import ParallelJawSpec, SuctionCupSpec, ToolSpec


def station_urdf(robot: RobotSpec, tool: ToolSpec) -> Path:
    """The URDF file of ``robot`` carrying ``tool`` (written once, then reused)."""
    source = resolve_urdf(robot.urdf)
    try:
        root = ET.parse(source).getroot()
    except (OSError, ET.ParseError) as exc:
        msg = f"{source}: cannot read the robot's URDF: {exc}"
        raise ConfigError(msg) from None
    _absolute_meshes(root, source.parent)
    _datasheet_limits(root, robot, source)
    if tool.mount == "flange":
        if not robot.flange_link:
            msg = f"robot {robot.name!r} has no flange_link: tool {tool.name!r} cannot be mounted"
            raise ConfigError(msg)
        _strip_below(root, robot.flange_link, source)
        root.extend(tool_elements(tool, robot.flange_link))
    text = ET.tostring(root, encoding="unicode")
    digest = hashlib.sha256(text.encode()).hexdigest()[:16]
    name = f"{robot.name}-{tool.name}-{digest}.urdf"
    for folder in (cache_root() / "urdf", Path(tempfile.gettempdir()) / "cdw-twin-urdf"):
        path = folder / name
        if path.is_file():
            return path
        try:
            write_atomic(path, text)
        except OSError:
            continue
        return path
    msg = f"cannot write the station URDF {name} (cache and temporary folders unwritable)"
    raise ConfigError(msg)


def _absolute_meshes(root: ET.Element, base: Path) -> None:
    """Every ``<mesh filename>`` as an absolute path (``package://`` resolved)."""
    for mesh in root.iter("mesh"):
        filename = mesh.get("filename", "")
        if filename.startswith("package://"):
            mesh.set("filename", str(_package_file(filename, base)))
        elif filename and not Path(filename).is_absolute():
            mesh.set("filename", str((base / filename).resolve()))


def _package_file(uri: str, base: Path) -> Path:
    """A ``package://`` mesh URI as a file: a package that ships robots here
    (:func:`interfaces.robots.package_root`), else, as PyBullet reads it, the path after
    ``package://`` relative to the URDF's folder."""
    path = uri.removeprefix("package://")
    package, _, rest = path.partition("/")
    if package in ("pybullet_data", "example-robot-data"):
        return package_root(package) / rest
    return (base / path).resolve()


def _joint(root: ET.Element, name: str, source: Path) -> ET.Element:
    for joint in root.findall("joint"):
        if joint.get("name") == name:
            return joint
    msg = f"{source}: no joint named {name!r}"
    raise ConfigError(msg)


def _datasheet_limits(root: ET.Element, robot: RobotSpec, source: Path) -> None:
    for i, name in enumerate(robot.arm_joints):
        limit = _joint(root, name, source).find("limit")
        if limit is None:
            continue
        if robot.joint_position_limits_rad:
            lower, upper = robot.joint_position_limits_rad[i]
            limit.set("lower", repr(lower))
            limit.set("upper", repr(upper))
        if robot.joint_max_velocity_rps:
            limit.set("velocity", repr(robot.joint_max_velocity_rps[i]))


def _strip_below(root: ET.Element, flange: str, source: Path) -> None:
    """Remove every link below ``flange`` and the joints, transmissions and gazebo tags of
    them."""
    if not any(link.get("name") == flange for link in root.findall("link")):
        msg = f"{source}: no link named {flange!r} (robot.flange_link)"
        raise ConfigError(msg)
    parents = {_attr(j, "child"): _attr(j, "parent") for j in root.findall("joint")}
    removed: set[str] = set()
    frontier = [flange]
    while frontier:
        link = frontier.pop()
        children = [child for child, parent in parents.items() if parent == link]
        removed.update(children)
        frontier.extend(children)
    removed_joints = {
        j.get("name", "") for j in root.findall("joint") if _attr(j, "child") in removed
    }
    for element in list(root):
        tag, name = element.tag, element.get("name", element.get("reference", ""))
        if (
            (tag == "link" and name in removed)
            or (tag == "joint" and name in removed_joints)
            or (tag == "gazebo" and name in removed | removed_joints)
            or (
                tag == "transmission"
                and any(j.get("name") in removed_joints for j in element.iter("joint"))
            )
        ):
            root.remove(element)


def _attr(joint: ET.Element, tag: str) -> str:
    element = joint.find(tag)
    return "" if element is None else element.get("link", "")


def tool_elements(tool: ToolSpec, flange: str) -> list[ET.Element]:
    """The links and joints of a flange-mounted tool, hung from ``flange``.

    Every tool's TCP frame has the flange's orientation: z along the tool's axis, out of the
    flange (the direction of approach when the tool points down), as the Panda hand's
    ``panda_grasptarget`` has; a jaw's fingers close along the TCP's y axis.
    """
    if isinstance(tool, SuctionCupSpec):
        return _suction_cup(tool, flange)
    if isinstance(tool, ParallelJawSpec):
        return _parallel_jaw(tool, flange)
    msg = f"tool {tool.name!r}: no flange geometry for its kind"
    raise ConfigError(msg)


def _xyz(x: float, y: float, z: float) -> str:
    return f"{x!r} {y!r} {z!r}"


def _link(
    name: str,
    mass_kg: float,
    *,
    box_m: tuple[float, float, float] | None = None,
    cylinder_m: tuple[float, float] | None = None,
    at_m: float = 0.0,
) -> ET.Element:
    """A link with a box (x, y, z) or cylinder (radius, length) shape centred ``at_m`` along
    z, and the inertia of that solid (none: a frame of negligible mass)."""
    link = ET.Element("link", name=name)
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "origin", xyz=_xyz(0.0, 0.0, at_m), rpy="0 0 0")
    ET.SubElement(inertial, "mass", value=repr(mass_kg))
    ixx = iyy = izz = 1e-6
    if box_m is not None:
        x, y, z = box_m
        ixx, iyy, izz = (mass_kg * (b * b + c * c) / 12.0 for b, c in ((y, z), (x, z), (x, y)))
    elif cylinder_m is not None:
        r, length = cylinder_m
        ixx = iyy = mass_kg * (3 * r * r + length * length) / 12.0
        izz = mass_kg * r * r / 2.0
    ET.SubElement(
        inertial, "inertia", ixx=repr(ixx), ixy="0", ixz="0", iyy=repr(iyy), iyz="0", izz=repr(izz)
    )
    for tag in ("visual", "collision") if (box_m or cylinder_m) else ():
        shape = ET.SubElement(link, tag)
        ET.SubElement(shape, "origin", xyz=_xyz(0.0, 0.0, at_m), rpy="0 0 0")
        geometry = ET.SubElement(shape, "geometry")
        if box_m is not None:
            ET.SubElement(geometry, "box", size=_xyz(*box_m))
        elif cylinder_m is not None:
            ET.SubElement(
                geometry, "cylinder", radius=repr(cylinder_m[0]), length=repr(cylinder_m[1])
            )
    return link


def _fixed(name: str, parent: str, child: str, z_m: float) -> ET.Element:
    joint = ET.Element("joint", name=name, type="fixed")
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=child)
    ET.SubElement(joint, "origin", xyz=_xyz(0.0, 0.0, z_m), rpy="0 0 0")
    return joint


SUCTION_LIP_CLEARANCE_M = 0.002
"""The stem's collision shape ends this far above the lip (the TCP): the cup's soft lip."""


def _suction_cup(tool: SuctionCupSpec, flange: str) -> list[ET.Element]:
    stem = f"{tool.name}_stem"
    length = tool.stem_length_m - SUCTION_LIP_CLEARANCE_M
    return [
        _fixed(f"{tool.name}_mount", flange, stem, 0.0),
        _link(stem, 0.4, cylinder_m=(tool.body_radius_m, length), at_m=0.5 * length),
        _fixed(f"{tool.name}_tcp_joint", stem, tool.tcp_link, tool.stem_length_m),
        _link(tool.tcp_link, 0.001),
    ]


def _parallel_jaw(tool: ParallelJawSpec, flange: str) -> list[ET.Element]:
    palm = f"{tool.name}_palm"
    half_stroke = 0.5 * tool.max_opening_m
    finger_box = (tool.finger_width_m, tool.finger_depth_m, tool.finger_length_m)
    elements = [
        _fixed(f"{tool.name}_mount", flange, palm, 0.0),
        _link(
            palm,
            0.9,
            box_m=(tool.hand_depth_m, tool.hand_width_m, tool.palm_height_m),
            at_m=0.5 * tool.palm_height_m,
        ),
    ]
    for joint_name, link_name, side in zip(tool.joints, tool.links, (1.0, -1.0), strict=True):
        joint = ET.Element("joint", name=joint_name, type="prismatic")
        ET.SubElement(joint, "parent", link=palm)
        ET.SubElement(joint, "child", link=link_name)
        inner_y = side * 0.5 * tool.finger_depth_m
        ET.SubElement(joint, "origin", xyz=_xyz(0.0, inner_y, tool.palm_height_m), rpy="0 0 0")
        ET.SubElement(joint, "axis", xyz=_xyz(0.0, side, 0.0))
        effort = tool.grip_force_N if tool.grip_force_N is not None else 200.0
        ET.SubElement(
            joint,
            "limit",
            lower="0.0",
            upper=repr(half_stroke),
            effort=repr(effort),
            velocity="0.2",
        )
        elements += [
            joint,
            _link(link_name, 0.1, box_m=finger_box, at_m=0.5 * tool.finger_length_m),
        ]
    tcp_z = tool.palm_height_m + tool.finger_length_m - 0.5 * tool.pad_height_m
    elements += [
        _fixed(f"{tool.name}_tcp_joint", palm, tool.tcp_link, tcp_z),
        _link(tool.tcp_link, 0.001),
    ]
    return elements


# -- reach ----------------------------------------------------------------------------------
@dataclass(frozen=True, kw_only=True)
class Reach:
    """How far a station's TCP can get: ``origin_m`` is the first arm joint's origin in the
    robot's base frame, ``reach_m`` an upper bound of the TCP's distance from it in any
    configuration (the sum of the fixed offsets between the following arm joints' origins and
    on to the TCP: the triangle inequality; loose where links are offset sideways, but what
    lies beyond it can never be reached). The same bound as the controller's IK uses."""

    origin_m: tuple[float, float, float]
    reach_m: float


def _rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def _numbers(text: str, where: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.split())
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        msg = f"{where}: expected three finite numbers, got {text[:80]!r}"
        raise ConfigError(msg)
    return values[0], values[1], values[2]


def _origin(joint: ET.Element, source: Path) -> np.ndarray:
    """The 4x4 transform of a joint's ``<origin>`` (the joint at its zero position)."""
    transform = np.eye(4)
    origin = joint.find("origin")
    if origin is None:
        return transform
    where = f"{source}: joint {joint.get('name', '')!r} origin"
    transform[:3, :3] = _rpy_matrix(*_numbers(origin.get("rpy", "0 0 0"), where))
    transform[:3, 3] = _numbers(origin.get("xyz", "0 0 0"), where)
    return transform


def station_reach(robot: RobotSpec, tool: ToolSpec) -> Reach:
    """The :class:`Reach` of ``robot`` carrying ``tool``, from the station's URDF
    (:func:`station_urdf`); :class:`ConfigError` naming the URDF when its chain from the base
    to the tool's TCP link does not pass through every arm joint."""
    path = station_urdf(robot, tool)
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        msg = f"{path}: cannot read the station's URDF: {exc}"
        raise ConfigError(msg) from None
    by_child = {_attr(j, "child"): j for j in root.findall("joint")}
    chain: list[ET.Element] = []
    link = tool.tcp_link
    if not any(element.get("name") == link for element in root.findall("link")):
        msg = f"{path}: tool {tool.name!r}: no link named {link!r} (tool.tcp_link)"
        raise ConfigError(msg)
    while link in by_child and len(chain) <= len(by_child):
        joint = by_child[link]
        chain.append(joint)
        link = _attr(joint, "parent")
    chain.reverse()
    names = [j.get("name", "") for j in chain]
    missing = [name for name in robot.arm_joints if name not in names]
    if missing:
        msg = (
            f"{path}: arm joints {missing} are not on the chain from the base to the TCP link "
            f"{tool.tcp_link!r} (robot.arm_joints, tool.tcp_link)"
        )
        raise ConfigError(msg)
    first = names.index(robot.arm_joints[0])
    to_first = np.eye(4)
    for joint in chain[: first + 1]:
        to_first = to_first @ _origin(joint, path)
    length_m = 0.0
    since = np.eye(4)
    for joint in chain[first + 1 :]:
        since = since @ _origin(joint, path)
        if joint.get("name") in robot.arm_joints:
            length_m += float(np.linalg.norm(since[:3, 3]))
            since = np.eye(4)
    tcp = since[:3, :3] @ np.asarray(tool.tcp_offset_m, dtype=float) + since[:3, 3]
    length_m += float(np.linalg.norm(tcp))
    x, y, z = (float(v) for v in to_first[:3, 3])
    return Reach(origin_m=(x, y, z), reach_m=length_m + 1e-6)
