"""``cdw-twin bench rtt``: round-trip latency between a client process and the twin node.

Starts the twin node (realtime, the standard 40-object scene on a prefilled belt, physics running)
in its own process on an isolated ROS domain, then pings it from this process at ``--rate`` Hz:
each ``Ping`` carries the client's monotonic send time and is echoed on ``/ping/echo`` by the twin
from inside its step loop. Prints ``p50_ms``, ``p95_ms``, ``p99_ms``, ``max_ms`` and ``lost``
(pings without an echo within 1 s of the last one sent).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from typing import Any

import numpy as np


def configure(parser: argparse.ArgumentParser) -> None:
    """Add the benchmark's options."""
    parser.add_argument("--rate", type=float, default=100.0, help="pings per second (100)")
    parser.add_argument("--count", type=int, default=2000, help="pings (2000)")
    parser.add_argument("--objects", type=int, default=40, help="objects in the scene (40)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def _twin_command(objects: int, seconds: float) -> list[str]:
    from twin.builtin import builtin_dataset

    dataset = builtin_dataset(dense=True)
    return [
        *(sys.executable, "-m", "twin.cli", "twin-node", "--mode", "realtime"),
        *("--dataset", str(dataset), "--objects", str(objects), "--prefill", "1.75"),
        *("--speed", "0.2", "--duration", f"{seconds:.1f}"),
    ]


def run(args: argparse.Namespace) -> int:
    """Run the benchmark."""
    import rclpy

    from interfaces.lifecycle import PARENT_PID_VARIABLE
    from twin.ros_isolation import clean_stale_fastdds_shm, ros_domain

    clean_stale_fastdds_shm()
    seconds = args.count / args.rate + 30.0
    with ros_domain() as domain:
        os.environ.update(domain.env)
        twin = subprocess.Popen(
            _twin_command(args.objects, seconds),
            env={**domain.env, PARENT_PID_VARIABLE: str(os.getpid())},
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
        rclpy.init()
        node = rclpy.create_node("rtt_client")
        try:
            result = _ping(node, twin, args)
        finally:
            node.destroy_node()
            rclpy.shutdown()
            twin.terminate()
            try:
                twin.wait(timeout=10)
            except subprocess.TimeoutExpired:
                twin.kill()
    if args.json:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            if key != "series_ms":
                print(f"{key:>10}: {value}")
    return 0


def _ping(node: Any, twin: subprocess.Popen[bytes], args: argparse.Namespace) -> dict[str, Any]:
    """Wait for the twin's clock, ping it ``args.count`` times, return the figures."""
    from cdw_interfaces.msg import Ping
    from rosgraph_msgs.msg import Clock

    from interfaces.contract import CLOCK_TOPIC, PING, PING_ECHO
    from interfaces.ros import qos_profile
    from twin.ros_node import make_executor

    executor = make_executor()
    executor.add_node(node)
    clock_seen = {"n": 0}
    rtts: dict[int, float] = {}
    sent: dict[int, int] = {}

    def on_clock(_: Clock) -> None:
        clock_seen["n"] += 1

    def on_echo(msg: Ping) -> None:
        now = time.monotonic_ns()
        if msg.seq in sent and msg.seq not in rtts:
            rtts[msg.seq] = (now - msg.client_send_ns) / 1e6

    node.create_subscription(Clock, CLOCK_TOPIC.name, on_clock, qos_profile(CLOCK_TOPIC.qos))
    node.create_subscription(Ping, PING_ECHO.name, on_echo, qos_profile(PING_ECHO.qos))
    pub = node.create_publisher(Ping, PING.name, qos_profile(PING.qos))
    deadline = time.monotonic() + 120.0
    while (
        clock_seen["n"] < 240 or pub.get_subscription_count() == 0
    ) and time.monotonic() < deadline:
        if twin.poll() is not None:
            err = twin.stderr.read().decode() if twin.stderr else ""
            msg = f"the twin node exited early: {err[-2000:]}"
            raise RuntimeError(msg)
        executor.spin_once(timeout_sec=0.05)
    period_ns = int(1e9 / args.rate)
    next_ns = time.monotonic_ns()
    for seq in range(args.count):
        while (wait := (next_ns - time.monotonic_ns()) / 1e9) > 0:
            executor.spin_once(timeout_sec=wait)
        sent[seq] = time.monotonic_ns()
        pub.publish(Ping(seq=seq, client_send_ns=sent[seq]))
        next_ns += period_ns
    end = time.monotonic() + 1.0
    while time.monotonic() < end and len(rtts) < len(sent):
        executor.spin_once(timeout_sec=0.05)
    values = np.array([rtts[s] for s in sorted(rtts)])
    return {
        "rate_hz": args.rate,
        "count": args.count,
        "objects": args.objects,
        "received": int(values.size),
        "lost": len(sent) - int(values.size),
        "p50_ms": float(np.percentile(values, 50)),
        "p95_ms": float(np.percentile(values, 95)),
        "p99_ms": float(np.percentile(values, 99)),
        "max_ms": float(values.max()),
        "mean_ms": float(values.mean()),
        "series_ms": [round(float(v), 4) for v in values],
    }
