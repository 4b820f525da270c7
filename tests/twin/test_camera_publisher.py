"""The camera publisher on the in-process bus with a real twin: nothing is rendered for nobody,
a subscriber gets every frame, the tap one in ``rate / record_hz``, and with the camera source
the frames the detector got are the ones sent (no second render)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from sensor_msgs.msg import Image

from interfaces.camera_topics import IMAGES, camera_topics
from interfaces.inproc import Bus
from twin.camera_publisher import CameraPublisher, record_hz_for
from twin.perception_config import PerceptionConfig
from twin.recording import open_cell_recording
from twin.ros_node import Tap
from twin.scenario import Scenario, SystemLevel
from twin.sim import Twin
from twin.tapped_wire import TappedWire

SECONDS = 1.0
RATE_HZ = 15.0


def _twin(source: str, meshes: Path) -> Twin:
    scenario = Scenario(
        name=f"publish-{source}",
        duration_s=SECONDS,
        system=SystemLevel(belt_speed_mps=0.4, prefill_m=1.2),
        perception=PerceptionConfig(source=source, rate_hz=RATE_HZ),
    )
    return Twin(scenario, dataset_dir=meshes)


def _run(
    twin: Twin,
    publisher: CameraPublisher,
    bus: Bus,
    tapped: list[str] | None,
    subscribe: bool,
    tap: Tap | None = None,
) -> list[Any]:
    """Attach ``publisher`` to a wire on ``bus`` (with a tap collecting topic names into
    ``tapped`` unless None, or ``tap``), step the twin ``SECONDS``, and return what a colour
    subscriber got (none unless ``subscribe``)."""
    if tapped is not None:
        tap = lambda topic, data, ns: tapped.append(topic)  # noqa: E731
    io = TappedWire(bus, takes_bytes=False, tap=tap, tap_wants=None)
    twin.reset(seed=2)
    publisher.attach(io, twin)
    got: list[Any] = []
    name = camera_topics(twin.cell.cameras[0].name).colour.name
    if subscribe:
        bus.create_subscription(Image, name, got.append, IMAGES)
    while twin.time_s < SECONDS - 1e-9:
        twin.advance()
        publisher.publish_step(None, twin.step_count)  # type: ignore[arg-type]
        bus.spin_once(timeout_sec=0.0)
    return got


@pytest.fixture(scope="module")
def oracle_twin(builtin_meshes: Path) -> Iterator[Twin]:
    with _twin("oracle", builtin_meshes) as twin:
        yield twin


def test_with_the_oracle_nothing_is_rendered_unless_someone_takes_it(
    oracle_twin: Twin,
) -> None:
    alone = CameraPublisher(record_hz=record_hz_for("oracle", None))
    _run(oracle_twin, alone, Bus(), tapped=[], subscribe=False)  # a recording, no subscriber
    assert alone.renders == 0
    assert alone.sent == {oracle_twin.cell.cameras[0].name: 0}

    watched = CameraPublisher(record_hz=0.0)
    got = _run(oracle_twin, watched, Bus(), tapped=None, subscribe=True)
    frames = round(SECONDS * oracle_twin.cell.cameras[0].rate_hz)
    assert watched.renders == len(got) == frames
    image = np.frombuffer(bytes(got[0].data), np.uint8).reshape(got[0].height, got[0].width, 3)
    assert image.std() > 5.0  # a picture of the belt and its pieces, not a blank


def test_the_tap_takes_one_frame_in_rate_over_record_hz(oracle_twin: Twin) -> None:
    tapped: list[str] = []
    publisher = CameraPublisher(record_hz=5.0)
    _run(oracle_twin, publisher, Bus(), tapped=tapped, subscribe=False)
    colour = camera_topics(oracle_twin.cell.cameras[0].name).colour.name
    assert tapped.count(colour) == round(SECONDS * 5.0)
    assert publisher.renders == round(SECONDS * 5.0)


def test_with_the_camera_source_the_detectors_frames_are_sent_and_recorded(
    builtin_meshes: Path, tmp_path: Path
) -> None:
    from mcap.reader import make_reader
    from rclpy.serialization import deserialize_message

    out = tmp_path / "recording.mcap"
    with _twin("camera", builtin_meshes) as twin:
        recording = open_cell_recording(out, twin.cell)
        assert recording is not None
        publisher = CameraPublisher(record_hz=5.0)
        got = _run(twin, publisher, Bus(), None, subscribe=True, tap=recording.write)
        recording.close()
        assert publisher.renders == 0
        # every frame drawn by the end (the last one, begun at the last step, is read back
        # at the next), one per 1 / RATE_HZ
        assert len(got) == round(SECONDS * RATE_HZ) - 1
        stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in got]
        assert np.allclose(np.diff(stamps), 1.0 / RATE_HZ, atol=twin.dt_s)
        last = twin.camera_frames()[0]
        image = np.frombuffer(bytes(got[-1].data), np.uint8).reshape(last.rgb.shape)
        assert np.array_equal(image, last.rgb)
        stamp = got[-1].header.stamp
        assert stamp.sec + 1e-9 * stamp.nanosec == pytest.approx(last.stamp_s, abs=1e-9)

    # the recording: the images under Foxglove's standard schema names, every frame sent
    # (the subscriber wanted them all), each one a whole image
    with out.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None
        schemas = {ch.topic: summary.schemas[ch.schema_id].name for ch in summary.channels.values()}
        colour = camera_topics(twin.cell.cameras[0].name).colour.name
        assert schemas[colour] == "sensor_msgs/msg/Image"
        frames = [m for _, ch, m in reader.iter_messages(topics=[colour])]
    assert len(frames) == len(got)
    back = deserialize_message(frames[-1].data, Image)
    assert (back.width, back.height, back.encoding) == (got[-1].width, got[-1].height, "rgb8")
