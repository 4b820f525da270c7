"""The worked example client (``docs/examples/pick_client.py``): its numbers are the page's, and
it sorts what it targets against a real twin node, over real ROS 2, in realtime.

The client is a stranger's: it copies the contract's numbers from ``docs/interfaces.md``. The
first test compares those copies with the page's tables (which the tests of the page compare
with what the twin loads), so a change of the contract that the client misses fails here.
"""

from __future__ import annotations

import importlib.util
import json
import re
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from process_helpers import finish, start_twin_node

from tests.docs.conftest import ROOT, Page, cells, ticked

CLIENT = ROOT / "docs" / "examples" / "pick_client.py"
EPISODE_S = 24.0
"""Sim seconds of the ROS episode: room for two picks at 0.2 m/s with the belt prefilled."""
MIN_SUCCESS = 0.8
"""The issue's target (sorted / targeted); see the test's docstring for the runs behind it."""


@pytest.fixture(scope="module")
def client() -> ModuleType:
    """The client imported as a module (it needs rclpy and the built ``cdw_interfaces``)."""
    if importlib.util.find_spec("cdw_interfaces") is None:
        pytest.skip("cdw_interfaces is not built: .venv/bin/python interfaces/build_interfaces.py")
    spec = importlib.util.spec_from_file_location("cdw_example_pick_client", CLIENT)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def _numbers(text: str) -> list[float]:
    return [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?", text)]


def _table(page: Page, title: str) -> dict[str, list[str]]:
    """A table of the page by its first cell (code spans unwrapped)."""
    return {cells(line)[0].strip("`"): cells(line)[1:] for line in page.rows(title)}


def test_the_clients_numbers_are_the_pages(interfaces_page: Page, client: ModuleType) -> None:
    limits = _table(interfaces_page, "Joint limits")
    assert list(limits) == list(client.ARM_JOINTS)
    columns = np.array([[float(v) for v in row[:4]] for row in limits.values()])
    for i, name in enumerate(("LOWER_RAD", "UPPER_RAD", "VELOCITY_RPS", "ACCELERATION_RPS2")):
        assert getattr(client, name).tolist() == columns[:, i].tolist(), name
    robot = _table(interfaces_page, "The robot")
    assert client.URDF.as_posix().endswith(ticked(robot["model"][0])[0])
    assert ticked(robot["finger joints"][0]) == list(client.FINGER_JOINTS)
    assert ticked(robot["TCP"][0])[0] == client.TCP_FRAME
    assert _numbers(robot["gripper opening"][0])[-1] == client.FULL_OPENING_M
    stations = [cells(line) for line in interfaces_page.rows("Stations")]
    (window,) = [row[5] for row in stations if row[0] == "`default`"]
    assert tuple(_numbers(window)) == client.PICK_WINDOW_X_M
    jaw = _table(interfaces_page, "Jaw geometry")["panda_hand"]
    assert _numbers(jaw[1]) == [client.PADS_GAP_M]
    assert _numbers(jaw[2]) == [client.PAD_HEIGHT_M]
    assert _numbers(jaw[3]) == [client.FINGER_HALF_X_M]
    assert _numbers(jaw[4]) == [client.FINGER_OUTER_Y_M]
    assert _numbers(jaw[5]) == [client.FINGERTIP_BEYOND_TCP_M]
    assert _numbers(jaw[6]) == [client.PALM_ABOVE_TCP_M]
    palm_x, palm_y = jaw[7].split(";")
    assert _numbers(palm_x) == [client.PALM_HALF_X_M]
    assert max(abs(v) for v in _numbers(palm_y)) == client.PALM_HALF_Y_M
    dwell = re.search(r"at least the dwell, ([\d.]+) s", interfaces_page.flat("Pick success"))
    assert dwell
    assert float(dwell.group(1)) == client.DWELL_S
    release = re.search(r"([\d.]+) m above the rim", interfaces_page.flat("Bins"))
    assert release
    assert float(release.group(1)) == client.DROP_ABOVE_RIM_M


def test_the_clients_joint_moves_keep_within_the_limits(client: ModuleType) -> None:
    """A long move from rest to a moving end: every sample within the limits in force."""
    q0 = np.array([0.0, -0.35, 0.0, -2.3, 0.0, 1.95, 0.785])
    q1 = np.clip(q0 + 1.5, client.LOWER_RAD, client.UPPER_RAD)
    v1 = 0.2 * client.VELOCITY_RPS
    move = client.JointMove.within_limits(q0, np.zeros(7), q1, v1, 0.0)
    for t in np.linspace(0.0, move.t1_s, 200):
        _, v, a = move.at(float(t))
        assert np.all(np.abs(v) <= client.VELOCITY_RPS)
        assert np.all(np.abs(a) <= client.ACCELERATION_RPS2)
    assert move.at(move.t1_s)[0] == pytest.approx(q1)


def _tail(proc: subprocess.Popen[bytes]) -> str:
    """The last lines a finished process wrote on its stderr (its log)."""
    return proc.stderr.read().decode()[-3000:] if proc.stderr is not None else ""


@pytest.mark.ros
def test_the_example_client_sorts_what_it_targets(
    builtin_meshes: Path, tmp_path: Path, client: ModuleType
) -> None:
    """A realtime episode at 0.2 m/s, the twin node and the client as two processes on a ROS
    domain of their own. Scored as ``docs/metrics.md`` says for a client of a hand-started twin:
    sorted / (pursuits less the objects still landing). In 10 runs of this episode on 2 busy
    cores the client targeted 2 pieces and sorted both every time (20 of 20)."""
    from twin.ros_isolation import clean_stale_fastdds_shm, ros_domain

    del client  # imported only to skip without the messages
    clean_stale_fastdds_shm()
    out = tmp_path / "episode"
    seconds = f"{EPISODE_S:g}"
    with ros_domain() as domain:
        peer = subprocess.Popen(
            [
                sys.executable,
                str(CLIENT),
                "--duration",
                seconds,
                "--stats",
                str(tmp_path / "c.json"),
            ],
            env=domain.env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
        )
        twin = start_twin_node(
            domain.env,
            [
                *("--dataset", str(builtin_meshes), "--speed", "0.2", "--mode", "realtime"),
                *("--seed", "1", "--prefill", "1.2", "--duration", seconds, "--out", str(out)),
            ],
        )
        try:
            assert finish(twin, EPISODE_S + 40.0) == 0, _tail(twin)
            assert finish(peer, 20.0) == 0, _tail(peer)
        finally:
            for proc in (twin, peer):
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    log = _tail(peer)
    done = summary["scores"]["sorted"]
    targeted = summary["tracking"]["pursuits"] - len(summary["landing_in_bins"])
    assert done >= 1, log
    assert done / targeted >= MIN_SUCCESS, log
    stats = json.loads((tmp_path / "c.json").read_text(encoding="utf-8"))
    assert stats["targeted"] == summary["tracking"]["pursuits"]  # one pursuit per target
