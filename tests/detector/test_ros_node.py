"""The detector node across real processes: a camera process publishes RGB-D frames, the node
(``python -m detector.cmd_node``) answers each with the frame's detections on
``/objects/detections``, stamped with the frame's capture stamp."""

from __future__ import annotations

import importlib.util
import json
import math
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from meshgen.config import MeshgenConfig
from meshgen.pipeline import mesh_dataset
from meshgen.sample import write_sample
from twin.ros_isolation import ros_domain

PEER = Path(__file__).with_name("camera_peer.py")
DEFAULT_CELL = Path(__file__).resolve().parents[2] / "interfaces" / "cells" / "default.yaml"


def _has(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


pytestmark = pytest.mark.skipif(
    not (_has("rclpy") and _has("cdw_interfaces")),
    reason="rclpy or the cdw_interfaces messages are not in this venv",
)


def _cell(tmp_path: Path) -> Path:
    """The reference cell with one overhead 640x480 camera over the belt's upstream part."""
    data = yaml.safe_load(DEFAULT_CELL.read_text(encoding="utf-8"))
    data["cameras"] = [
        {
            "name": "top",
            "position_m": [-0.9, 0.5, 1.2],
            "rpy_rad": [0.0, math.pi / 2, math.pi],
            "width_px": 640,
            "height_px": 480,
            "hfov_deg": 60.0,
        }
    ]
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


def test_the_node_answers_each_frame_with_its_detections(tmp_path: Path) -> None:
    write_sample(tmp_path / "sample", images=6, seed=3)
    mesh_dataset(tmp_path / "sample", tmp_path / "meshes", MeshgenConfig(seed=3))
    cell = _cell(tmp_path)
    stats = tmp_path / "stats.json"
    with ros_domain() as domain:
        node = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "detector.cmd_node",
                "--dataset",
                str(tmp_path / "meshes"),
                "--cell",
                str(cell),
                "--duration",
                "60",
                "--stats-out",
                str(stats),
            ],
            env=domain.env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            peer = subprocess.run(
                [sys.executable, str(PEER), "--cell", str(cell), "--frames", "3"],
                env=domain.env,
                capture_output=True,
                text=True,
                timeout=90,
                check=False,
            )
        finally:
            node.send_signal(signal.SIGTERM)
            _, node_err = node.communicate(timeout=20)
    assert peer.returncode == 0, peer.stderr[-2000:]
    assert node.returncode == 0, node_err[-2000:]
    frames = json.loads(peer.stdout)["frames"]
    assert len(frames) == 3
    right = total = 0
    for frame in frames:
        detections = frame["detections"]
        assert detections is not None, f"no answer to the frame stamped {frame['stamp_ns']} ns"
        assert frame["frame_id"] == "world"
        truth = frame["truth"]
        assert len(detections) == len(truth)
        for name, x, y, top in truth:
            # the nearest detection: within 1 cm of the piece's centre, of its height
            nearest = min(detections, key=lambda d: math.hypot(d[1] - x, d[2] - y))
            assert math.hypot(nearest[1] - x, nearest[2] - y) < 0.01
            assert nearest[3] == pytest.approx(0.0, abs=0.005)  # lying on the belt
            assert nearest[4] == pytest.approx(top, abs=0.006)
            right += nearest[0] == name
            total += 1
    assert right / total >= 0.9
    counters = json.loads(stats.read_text(encoding="utf-8"))
    assert counters["frames"] >= 3
    assert counters["images_refused"] == 0
