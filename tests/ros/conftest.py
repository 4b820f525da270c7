"""Fixtures for the ROS 2 tests: an isolated domain per test and helpers to run real nodes."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from twin.ros_isolation import clean_stale_fastdds_shm, ros_domain

NODES_SCRIPT = Path(__file__).with_name("ros_nodes.py")
START_TIMEOUT_S = 20.0


def _has_module(name: str) -> bool:
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:
        return False


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark every test here ``ros``; skip those that run nodes when rclpy is missing."""
    here = Path(__file__).parent
    for item in items:
        if here in Path(item.path).parents:
            item.add_marker(pytest.mark.ros)
            if "nodes" in getattr(item, "fixturenames", ()) and not _has_module("rclpy"):
                item.add_marker(pytest.mark.skip(reason="rclpy is not installed in this venv"))


@pytest.fixture(scope="session", autouse=True)
def _clean_shm_once() -> None:
    clean_stale_fastdds_shm()


@pytest.fixture
def require_interfaces() -> None:
    """Skip unless the cdw_interfaces message package is built into this venv."""
    if not _has_module("cdw_interfaces"):
        pytest.skip(
            "cdw_interfaces is not built; run `.venv/bin/python interfaces/build_interfaces.py`"
        )


@pytest.fixture
def ros_env() -> Iterator[dict[str, str]]:
    """A process environment on a ROS domain no other test or run is using."""
    with ros_domain() as domain:
        yield domain.env


@pytest.fixture
def ros_env_factory() -> Iterator[Any]:
    """Claims further isolated domains on demand; all are released after the test."""
    from contextlib import ExitStack

    with ExitStack() as stack:
        yield lambda: stack.enter_context(ros_domain()).env


@pytest.fixture(scope="session")
def nodes_module() -> ModuleType:
    """``ros_nodes.py`` imported as a module (for its sample messages)."""
    spec = importlib.util.spec_from_file_location("cdw_test_ros_nodes", NODES_SCRIPT)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@dataclass
class NodeProcess:
    """A running ``ros_nodes.py`` process that has printed ``ready``."""

    process: subprocess.Popen[str]

    @property
    def pid(self) -> int:
        """Process id."""
        return self.process.pid

    def stop(self) -> int:
        """Close its stdin (the signal to exit) and wait; returns the exit status."""
        if self.process.stdin is not None and not self.process.stdin.closed:
            self.process.stdin.close()
        try:
            return self.process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            return self.process.wait()


class Nodes:
    """Starts ``ros_nodes.py`` processes and stops every one left running."""

    def __init__(self) -> None:
        self._started: list[NodeProcess] = []

    def start(self, env: dict[str, str], *args: str) -> NodeProcess:
        """Start a long-running mode (publish, idle) and wait until it prints ``ready``."""
        process = subprocess.Popen(
            [sys.executable, str(NODES_SCRIPT), *args],
            env=env,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        node = NodeProcess(process)
        self._started.append(node)
        assert process.stdout is not None
        line = process.stdout.readline().strip()
        if line != "ready":
            node.stop()
            pytest.fail(f"{args} did not start: first line {line!r}, exit {process.returncode}")
        return node

    def start_receiver(self, env: dict[str, str], *args: str) -> subprocess.Popen[str]:
        """Start ``receive`` without waiting; read its result with :meth:`result`."""
        return subprocess.Popen(
            [sys.executable, str(NODES_SCRIPT), "receive", *args],
            env=env,
            stdout=subprocess.PIPE,
            text=True,
        )

    @staticmethod
    def result(process: subprocess.Popen[str]) -> tuple[int, dict[str, list[Any]]]:
        """Wait for a receiver; returns its exit status and the JSON it printed."""
        stdout, _ = process.communicate(timeout=START_TIMEOUT_S + 10)
        return process.returncode, json.loads(stdout)

    def stop_all(self) -> None:
        """Stop every process this helper started."""
        for node in self._started:
            node.stop()


@pytest.fixture
def nodes() -> Iterator[Nodes]:
    """Runs real ROS node processes for one test."""
    helper = Nodes()
    yield helper
    helper.stop_all()
