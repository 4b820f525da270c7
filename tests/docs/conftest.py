"""Fixtures for the tests of the contract's pages: the pages' sections and tables, and the
robots and tools of the shipped cells as the twin loads them in PyBullet (with a probe that
measures where a link's collision shape reaches in the TCP frame)."""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as pb
import pytest

from interfaces.cell import CELLS_DIR, DEFAULT_CELL, Cell, StationSpec, load_cell
from interfaces.tools import ParallelJawSpec
from interfaces.urdf import station_urdf
from twin.robot import Robot
from twin.tools import Tool, make_tool

ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Page:
    """One markdown page of ``docs/``: its sections and tables."""

    path: Path

    @property
    def text(self) -> str:
        """The whole page."""
        return self.path.read_text(encoding="utf-8")

    def section(self, title: str) -> str:
        """The text of the section (any level) titled ``title``, up to the next heading."""
        match = re.search(rf"^#+ {re.escape(title)}\n(.*?)(?=^#+ |\Z)", self.text, re.M | re.S)
        assert match, f"{self.path.name} has no section {title!r}"
        return match.group(1)

    def flat(self, title: str) -> str:
        """The section's text with every run of whitespace one space (prose across lines)."""
        return " ".join(self.section(title).split())

    def rows(self, title: str) -> list[str]:
        """The body rows of the first table in the section (header and rule dropped)."""
        return [line for line in self.section(title).splitlines() if line.startswith("|")][2:]


def cells(row: str) -> list[str]:
    """The cells of a table row, stripped."""
    return [cell.strip() for cell in row.strip().strip("|").split("|")]


def ticked(text: str) -> list[str]:
    """Every ``code`` span of ``text``."""
    return re.findall(r"`([^`]+)`", text)


def row(*values: str) -> str:
    """A table row as the pages write it."""
    return "| " + " | ".join(values) + " |"


def num(value: float, digits: int = 4) -> str:
    """``value`` with ``digits`` decimals, never ``-0.0000``."""
    text = f"{value:.{digits}f}"
    return "0." + "0" * digits if float(text) == 0.0 else text


def short(value: float, digits: int = 4) -> str:
    """``value`` rounded to ``digits`` decimals (0.1 mm, 0.0001 rad), as few digits as it
    needs, never ``-0``."""
    rounded = round(value, digits)
    return f"{0.0 if rounded == 0 else rounded:g}"


def assert_rows(page: Page, title: str, expected: list[str]) -> None:
    """The first table of the section reads ``expected`` (the message shows the rows)."""
    got = page.rows(title)
    assert got == expected, f"the table of {title!r} should read:\n" + "\n".join(expected)


@pytest.fixture(scope="session")
def interfaces_page() -> Page:
    """``docs/interfaces.md``."""
    return Page(ROOT / "docs" / "interfaces.md")


@pytest.fixture(scope="session")
def metrics_page() -> Page:
    """``docs/metrics.md``."""
    return Page(ROOT / "docs" / "metrics.md")


def shipped_cells() -> list[tuple[Path, Cell]]:
    """Every shipped cell file and its cell, the reference first, then by name."""
    others = sorted(p for p in CELLS_DIR.glob("*.yaml") if p != DEFAULT_CELL)
    return [(path, load_cell(path)) for path in [DEFAULT_CELL, *others]]


@dataclass
class Loaded:
    """A station's robot and tool in a PyBullet client of their own, at the start pose."""

    station: StationSpec
    robot: Robot
    tool: Tool

    @property
    def client(self) -> int:
        """The PyBullet client."""
        return self.robot.client

    def link_pose(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        """World position ``(3,)`` and rotation ``(3, 3)`` of a link's URDF frame."""
        index = self.robot.link_index(link, "link")
        state = pb.getLinkState(
            self.robot.body, index, computeForwardKinematics=True, physicsClientId=self.client
        )
        rotation = np.array(pb.getMatrixFromQuaternion(state[5])).reshape(3, 3)
        return np.array(state[4]), rotation

    def tcp(self) -> tuple[np.ndarray, np.ndarray]:
        """World position ``(3,)`` and rotation ``(3, 3)`` of the TCP (as the twin reads it)."""
        position, orientation = self.tool.tcp_pose()
        return np.array(position), np.array(pb.getMatrixFromQuaternion(orientation)).reshape(3, 3)

    def in_tcp(self, link: str) -> np.ndarray:
        """The origin of a link's frame in the TCP frame ``(3,)``."""
        position, _ = self.link_pose(link)
        tcp, rotation = self.tcp()
        return np.asarray(rotation.T @ (position - tcp))

    def reach(self, link: str, axis: int, sign: float) -> float:
        """How far the link's collision shape reaches along ``sign`` times the TCP frame's axis
        ``axis`` (m, from the TCP): a large box with its face 1 m from the TCP along that
        direction, and the physics' closest distance from the link to it."""
        tcp, rotation = self.tcp()
        direction = sign * rotation[:, axis]
        half_m, face_m = 2.0, 1.0
        probe = pb.createCollisionShape(
            pb.GEOM_BOX, halfExtents=[half_m] * 3, physicsClientId=self.client
        )
        _, orientation = self.tool.tcp_pose()
        points = pb.getClosestPoints(
            bodyA=self.robot.body,
            bodyB=-1,
            distance=2 * face_m,
            linkIndexA=self.robot.link_index(link, "link"),
            collisionShapeB=probe,
            collisionShapePositionB=(tcp + direction * (face_m + half_m)).tolist(),
            collisionShapeOrientationB=orientation,
            physicsClientId=self.client,
        )
        pb.removeCollisionShape(probe, physicsClientId=self.client)
        assert points, f"{link} has no collision shape within reach of the probe"
        return face_m - float(min(p[8] for p in points))

    def gap(self, link_a: str, link_b: str) -> float:
        """The physics' closest distance between two links (m; negative: they interpenetrate)."""
        points = pb.getClosestPoints(
            bodyA=self.robot.body,
            bodyB=self.robot.body,
            distance=1.0,
            linkIndexA=self.robot.link_index(link_a, "link"),
            linkIndexB=self.robot.link_index(link_b, "link"),
            physicsClientId=self.client,
        )
        return float(min(p[8] for p in points))

    def set_fingers(self, fraction_open: float) -> None:
        """Put a jaw's finger joints at ``fraction_open`` of the way from closed to open."""
        spec = self.tool.spec
        assert isinstance(spec, ParallelJawSpec), spec.name
        for name, q_open, q_closed in zip(
            spec.joints, spec.joint_open, spec.joint_closed, strict=True
        ):
            joint = self.robot.joint_index(name, "finger joint")
            q = q_closed + fraction_open * (q_open - q_closed)
            pb.resetJointState(self.robot.body, joint, q, 0.0, physicsClientId=self.client)


@pytest.fixture(scope="module")
def load_station() -> Iterator[Callable[[StationSpec], Loaded]]:
    """Loads stations as the twin does (the station's URDF in PyBullet, the twin's tool on it),
    each in a client of its own, the arm at home and the tool open; all closed afterwards."""
    clients: list[int] = []

    def load(station: StationSpec) -> Loaded:
        client = pb.connect(pb.DIRECT)
        clients.append(client)
        robot = Robot(client, station.robot, urdf=station_urdf(station.robot, station.tool))
        tool = make_tool(station.tool, robot)
        robot.reset_state()
        tool.reset_state()
        return Loaded(station=station, robot=robot, tool=tool)

    yield load
    for client in clients:
        pb.disconnect(physicsClientId=client)


def yaw_of_down(rotation: np.ndarray) -> float | None:
    """The yaw of a rotation ``(3, 3)`` that points its z down (``Rz(yaw) Rx(pi)``), None when it
    does not point down."""
    if float(rotation[:, 2] @ np.array([0.0, 0.0, -1.0])) < 1.0 - 1e-6:
        return None
    return math.atan2(float(rotation[1, 0]), float(rotation[0, 0]))
