"""The real nodes against :mod:`interfaces.contract` (which ``docs/interfaces.md`` is checked
against, ``tests/twin/test_interfaces_doc.py``), and what the twin node latches.

A real :class:`twin.ros_node.TwinNode` (around a real twin, for the reference cell and for the
two-station ``two_pandas`` cell) and a real :class:`control.node.ControllerNode` are created in
this process on an isolated domain; their publishers and subscriptions, with types and QoS, are
compared with the contract resolved for the cell's station namespaces, so neither the code nor
the page can drift from the contract.
"""

# rclpy's annotations are partial.
# mypy: disable-error-code="no-untyped-call"

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

import pytest
from twin_helpers import box_px

from interfaces import contract
from interfaces.camera_topics import camera_topics
from interfaces.cell import Cell, default_cell, load_cell
from interfaces.cell_topics import cell_topics
from twin.scenario import FaultLevel, Scenario, SystemLevel
from twin.sim import Twin

pytestmark = pytest.mark.usefixtures("require_interfaces")

ONE_BOX = {"img": [(1, box_px(500, 500, 100, 50))]}
ROS_OWN_TOPICS = {"/rosout", "/parameter_events"}


class Qos(NamedTuple):
    """Type and QoS of a topic, as the contract states them."""

    msg_type: str
    reliability: str
    durability: str
    depth: int


def _expected(topics: tuple[contract.Topic, ...], cell: Cell) -> dict[str, Qos]:
    """Wire name -> type and QoS of ``topics`` in ``cell`` (station topics once per station,
    camera topics once per camera)."""
    return {
        wire: Qos(
            f"{t.package}/{t.type_name}",
            "reliable" if t.qos.reliable else "best effort",
            "transient local" if t.qos.latched else "volatile",
            t.qos.depth,
        )
        for wire, t in cell_topics(cell)
        if t in topics
    }


def _of(endpoint: Any) -> Qos:
    """Type and QoS of a real publisher or subscription."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy

    qos = endpoint.qos_profile
    assert qos.history == HistoryPolicy.KEEP_LAST, endpoint.topic_name
    msg_type = endpoint.msg_type
    reliability = {
        ReliabilityPolicy.RELIABLE: "reliable",
        ReliabilityPolicy.BEST_EFFORT: "best effort",
    }[qos.reliability]
    durability = {
        DurabilityPolicy.VOLATILE: "volatile",
        DurabilityPolicy.TRANSIENT_LOCAL: "transient local",
    }[qos.durability]
    return Qos(
        f"{msg_type.__module__.split('.')[0]}/{msg_type.__name__}",
        reliability,
        durability,
        int(qos.depth),
    )


def _endpoints(items: Iterator[Any]) -> dict[str, Qos]:
    return {e.topic_name: _of(e) for e in items if e.topic_name not in ROS_OWN_TOPICS}


@pytest.fixture
def ros(ros_env: dict[str, str]) -> Iterator[Any]:
    """rclpy initialised on an isolated domain, with an executor; shut down after the test."""
    import rclpy
    from rclpy.experimental.events_executor import EventsExecutor

    saved = dict(os.environ)
    os.environ.update(ros_env)
    rclpy.init()
    executor = EventsExecutor()
    try:
        yield executor
    finally:
        executor.shutdown()
        rclpy.shutdown()
        os.environ.clear()
        os.environ.update(saved)


def _twin(meshes: Path, cell: Cell) -> Twin:
    """A real twin with one object; 0.2 s long, a detection dropout from 0.05 s to 0.1 s."""
    scenario = Scenario(
        duration_s=0.2,
        system=SystemLevel(belt_speed_mps=0.2, prefill_m=1.7, repeat_images=False),
        faults=FaultLevel(detection_dropout=((0.05, 0.1),)),
    )
    twin = Twin(scenario, dataset_dir=meshes, cell=cell)
    twin.reset(seed=0)
    return twin


@pytest.fixture
def twin(mesh_polygons: Callable[..., Path]) -> Iterator[Twin]:
    """A real twin of the reference cell (see :func:`_twin`)."""
    with _twin(mesh_polygons(ONE_BOX), default_cell()) as twin:
        yield twin


def _spin_until(executor: Any, done: Callable[[], bool], timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not done():
        assert time.monotonic() < deadline, "timed out"
        executor.spin_once(timeout_sec=0.02)


@pytest.mark.parametrize("cell_name", ["default", "two_pandas"])
def test_the_twin_nodes_topics_types_and_qos_are_the_contracts(
    ros: Any, mesh_polygons: Callable[..., Path], cell_name: str
) -> None:
    from twin.camera_publisher import CameraPublisher
    from twin.ros_node import TwinNode

    cell = load_cell(cell_name)
    with _twin(mesh_polygons(ONE_BOX), cell) as twin:
        node = TwinNode(twin, lockstep=True, step_publishers=(CameraPublisher(),))
        try:
            published = _endpoints(node.publishers)
            subscribed = _endpoints(node.subscriptions)
        finally:
            node.destroy_node()
    cameras = tuple(t for spec in cell.cameras for t in camera_topics(spec.name).all)
    assert cameras, f"the shipped cell {cell_name} has a camera"
    assert published == _expected(contract.PUBLISHED + cameras, cell)
    assert subscribed == _expected(contract.SUBSCRIBED, cell)
    if cell_name == "default":  # one station, empty namespace: today's bare names
        assert "/joint_states" in published
        assert "/arm_controller/joint_trajectory" in subscribed


def test_the_controller_uses_the_contracts_qos_on_every_topic(ros: Any, twin: Twin) -> None:
    """The controller's side of each topic it uses (its ack publisher is created once its
    readers have matched the twin's writers, so both nodes run here)."""
    from control.config import ControllerConfig
    from control.node import ControllerNode
    from twin.ros_node import TwinNode

    twin_node = TwinNode(twin, lockstep=True)
    controller = ControllerNode(ControllerConfig(), lockstep=True)
    ros.add_node(twin_node)
    ros.add_node(controller)
    try:
        _spin_until(ros, lambda: controller.pub_ack is not None)
        published = _endpoints(controller.publishers)
        subscribed = _endpoints(controller.subscriptions)
    finally:
        controller.destroy_node()
        twin_node.destroy_node()
    cell = default_cell()
    cell_in = _expected(contract.SUBSCRIBED, cell)
    cell_out = _expected(contract.PUBLISHED, cell)
    assert set(published) == {
        "/arm_controller/joint_trajectory",
        "/gripper/command",
        "/controller/target",
        "/lockstep/ack",
        "/line/claim",
    }
    assert published == {topic: cell_in[topic] for topic in published}
    assert "/sorting/priorities" in subscribed
    assert "/line/claims" in subscribed  # the board, counted by the tick
    every = {**cell_out, **cell_in}  # /sorting/priorities: the controller reads it too
    assert subscribed == {topic: every[topic] for topic in subscribed}


def test_a_late_subscriber_gets_the_bins_and_every_logged_event(ros: Any, twin: Twin) -> None:
    """``/cell/bins`` is latched from the start; ``/events`` carries every event the twin logs,
    injected faults included (they used to stay in the episode log only)."""
    import rclpy
    from cdw_interfaces.msg import SortingBins, SortingEvent

    from interfaces.ros import qos_profile
    from twin.ros_node import TwinNode, run_loop

    twin_node = TwinNode(twin, lockstep=False)
    ros.add_node(twin_node)
    run_loop(twin_node, ros)
    listener = rclpy.create_node("late_listener")
    bins: list[Any] = []
    events: list[Any] = []
    listener.create_subscription(
        SortingBins, contract.BINS.resolve(""), bins.append, qos_profile(contract.BINS.qos)
    )
    listener.create_subscription(
        SortingEvent,
        contract.EVENTS_TOPIC.name,
        events.append,
        qos_profile(contract.EVENTS_TOPIC.qos),
    )
    ros.add_node(listener)
    try:
        _spin_until(ros, lambda: bool(bins) and len(events) >= len(twin.events))
    finally:
        listener.destroy_node()
        twin_node.destroy_node()
    (msg,) = bins
    assert msg.header.frame_id == "world"
    got = [
        (b.class_name, b.position.x, b.position.y, b.position.z, b.inner_half_m, b.size_m)
        for b in msg.bins
    ]
    assert got == [
        (b.class_name, b.centre_x_m, b.centre_y_m, b.top_z_m, b.inner_half_m, b.size_m)
        for b in default_cell().bins
    ]
    assert [(e.type, e.object_id) for e in events] == [
        (str(e.type), e.object_id) for e in twin.events
    ]
    faults = [e.detail for e in events if e.type == "fault"]
    assert len(faults) == 2
    assert all("injected_detection_dropout" in text for text in faults)
