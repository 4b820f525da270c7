"""Every message type crosses a real process boundary intact; domains keep runs apart."""

from __future__ import annotations

import json
import math
from types import ModuleType
from typing import Any

import pytest

pytestmark = pytest.mark.usefixtures("require_interfaces")


def _expected(nodes_module: ModuleType, token: int) -> dict[str, Any]:
    samples = nodes_module.sample_messages(token)
    return {topic: nodes_module.to_plain(message) for topic, message in samples.items()}


def test_every_message_type_round_trips(
    nodes: Any, nodes_module: ModuleType, ros_env: dict[str, str]
) -> None:
    token = 7
    nodes.start(ros_env, "publish", "--token", str(token))
    status, received = nodes.result(nodes.start_receiver(ros_env))

    expected = _expected(nodes_module, token)
    assert status == 0, f"missing topics: {sorted(set(expected) - set(received))}"
    assert set(received) == set(expected)
    for topic, messages in received.items():
        assert messages == [expected[topic]], topic

    ping = received["/rt/ping"][0]
    assert ping["client_send_ns"] == -123_456_789_012
    assert ping["sim_step"] == 2**40 + token
    assert ping["echo_ns"] == 2**62
    assert received["/rt/step_ack"][0] == {
        "tick": 2**33 + token,
        "n_commands": 3,
        "next_tick": 2**33 + token + 2,
    }
    detection = received["/rt/detection"][0]
    assert detection["confidence"] == 0.875
    assert math.isclose(detection["width_m"], 0.19)
    event = received["/rt/event"][0]
    assert event["class_name"] == "métal"
    assert json.loads(event["detail"]) == {"bin": "metal", "x_m": 1.5, "token": token}
    objects = received["/rt/object_states"][0]["objects"]
    assert [obj["id"] for obj in objects] == [token, token + 1]
    assert objects[0]["held"] is True
    assert objects[0]["in_bin"] is False
    assert received["/rt/clock"][0]["clock"] == {"sec": token, "nanosec": 999_999_999}
    point = received["/rt/joint_trajectory"][0]["points"][0]
    assert point["time_from_start"] == {"sec": 1, "nanosec": 500_000_000}


def test_parallel_pairs_on_separate_domains_do_not_cross_talk(
    nodes: Any, nodes_module: ModuleType, ros_env_factory: Any
) -> None:
    env_a, env_b = ros_env_factory(), ros_env_factory()
    assert env_a["ROS_DOMAIN_ID"] != env_b["ROS_DOMAIN_ID"]
    nodes.start(env_a, "publish", "--token", "1001")
    nodes.start(env_b, "publish", "--token", "2002")
    receiver_a = nodes.start_receiver(env_a, "--linger-s", "2.0")
    receiver_b = nodes.start_receiver(env_b, "--linger-s", "2.0")
    results = {1001: nodes.result(receiver_a), 2002: nodes.result(receiver_b)}

    for token, (status, received) in results.items():
        expected = _expected(nodes_module, token)
        assert status == 0, f"pair {token} missed {sorted(set(expected) - set(received))}"
        for topic, messages in received.items():
            assert messages == [expected[topic]], f"pair {token} got foreign data on {topic}"


def test_same_domain_does_cross_talk(
    nodes: Any, nodes_module: ModuleType, ros_env: dict[str, str]
) -> None:
    """Control for the test above: on one domain a receiver does see both publishers."""
    nodes.start(ros_env, "publish", "--token", "1001")
    nodes.start(ros_env, "publish", "--token", "2002")
    receiver = nodes.start_receiver(ros_env, "--per-topic", "2", "--linger-s", "0.5")
    status, received = nodes.result(receiver)

    assert status == 0, "a receiver on a shared domain did not hear both publishers"
    pings = sorted(message["seq"] for message in received["/rt/ping"])
    assert pings == [1001, 2002]
