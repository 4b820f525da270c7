"""A camera on ROS 2 for the detector node's test: publishes synthetic RGB-D frames of a cell's
camera and collects the detections that come back; prints JSON (truth and detections per frame).

Run as its own process: ``python camera_peer.py --cell CELL.yaml --frames 3 --pieces 8``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from typing import Any

import numpy as np
import rclpy
import rclpy.utilities
from cdw_interfaces.msg import DetectionArray
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.node import Node
from sensor_msgs.msg import CameraInfo, Image

from detector.synthetic import render, scatter
from interfaces.camera import DepthNoise, RgbdFrame, camera_info
from interfaces.camera_topics import camera_topics
from interfaces.cell import load_cell
from interfaces.contract import DETECTIONS, stamp_ns
from interfaces.materials import shipped_table
from interfaces.ros import qos_profile, time_msg

CLASSES = ("concrete", "brick", "wood")


def _image(frame: RgbdFrame, data: np.ndarray, encoding: str, frame_id: str) -> Image:
    msg = Image()
    msg.header.stamp = time_msg(frame.stamp_s)
    msg.header.frame_id = frame_id
    msg.height, msg.width = int(data.shape[0]), int(data.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.step = int(data.strides[0])
    msg.data = data.tobytes()
    return msg


def _info(info: Any, stamp_s: float) -> CameraInfo:
    msg = CameraInfo()
    msg.header.stamp = time_msg(stamp_s)
    msg.header.frame_id = info.frame_id
    msg.width, msg.height = info.width, info.height
    msg.distortion_model = info.distortion_model
    msg.d, msg.k, msg.r, msg.p = list(info.d), list(info.k), list(info.r), list(info.p)
    return msg


def _class_colours() -> dict[str, tuple[int, int, int]]:
    """The shipped class table's colours of :data:`CLASSES`, 0-255."""
    table = shipped_table()
    colours: dict[str, tuple[int, int, int]] = {}
    for name in CLASSES:
        red, green, blue = table.material(name).colour
        colours[name] = (round(255 * red), round(255 * green), round(255 * blue))
    return colours


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cell", required=True)
    parser.add_argument("--frames", type=int, default=3)
    parser.add_argument("--pieces", type=int, default=8)
    parser.add_argument("--timeout-s", type=float, default=30.0)
    args = parser.parse_args()
    cell = load_cell(args.cell)
    spec = cell.cameras[0]
    belt_z = cell.belt.surface_z_m
    colours = _class_colours()
    rclpy.init()
    node = Node("camera_peer")
    topics = camera_topics(spec.name)
    qos = qos_profile(topics.colour.qos)
    pub_colour = node.create_publisher(Image, topics.colour.name, qos)
    pub_depth = node.create_publisher(Image, topics.depth.name, qos)
    pub_info = node.create_publisher(CameraInfo, topics.info.name, qos)
    received: dict[int, Any] = {}

    def on_detections(msg: Any) -> None:
        received.setdefault(stamp_ns(msg.header.stamp.sec, msg.header.stamp.nanosec), msg)

    node.create_subscription(
        DetectionArray, DETECTIONS.name, on_detections, qos_profile(DETECTIONS.qos)
    )
    executor = EventsExecutor()
    executor.add_node(node)
    deadline = time.monotonic() + args.timeout_s
    while time.monotonic() < deadline and not (
        node.count_subscribers(topics.colour.name) >= 1
        and node.count_subscribers(topics.depth.name) >= 1
        and node.count_publishers(DETECTIONS.name) >= 1
    ):
        executor.spin_once(timeout_sec=0.05)
    time.sleep(0.3)
    info = camera_info(spec)
    frames = []
    for i in range(args.frames):
        pieces = scatter(
            args.pieces, seed=100 + i, area_m=(0.8, 0.5), colours=list(colours.values())
        )
        pieces = [
            dataclasses.replace(p, x_m=p.x_m + spec.position_m[0], y_m=p.y_m + cell.belt.centre_y_m)
            for p in pieces
        ]
        stamp_s = 1.0 + 0.5 * i
        frame = render(
            pieces, camera=spec, belt_z_m=belt_z, noise=DepthNoise(), seed=i, stamp_s=stamp_s
        )
        info_msg = _info(info, stamp_s)
        key = stamp_ns(info_msg.header.stamp.sec, info_msg.header.stamp.nanosec)
        sent_at = time.monotonic()
        for _attempt in range(3):
            pub_info.publish(info_msg)
            pub_depth.publish(_image(frame, frame.depth_m.astype("<f4"), "32FC1", info.frame_id))
            pub_colour.publish(_image(frame, frame.rgb, "rgb8", info.frame_id))
            until = time.monotonic() + 5.0
            while key not in received and time.monotonic() < until:
                executor.spin_once(timeout_sec=0.02)
            if key in received:
                break
        msg = received.get(key)
        name_of = {v: k for k, v in colours.items()}
        frames.append(
            {
                "stamp_ns": key,
                "latency_s": time.monotonic() - sent_at,
                "truth": [[name_of[p.rgb], p.x_m, p.y_m, p.top_z_m - belt_z] for p in pieces],
                "detections": None
                if msg is None
                else [
                    [d.class_name, d.position.x, d.position.y, d.position.z, d.height_m]
                    for d in msg.detections
                ],
                "frame_id": None if msg is None else msg.header.frame_id,
            }
        )
    node.destroy_node()  # type: ignore[no-untyped-call]
    rclpy.utilities.try_shutdown()
    sys.stdout.write(json.dumps({"frames": frames}) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
