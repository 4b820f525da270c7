"""The twin node trusts no client: a real rclpy client process sends hostile claims and
oversized messages; every one is refused and counted, the board stays bounded, the event log
does not flood."""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path

import pytest
from process_helpers import finish, start, start_twin_node

pytestmark = pytest.mark.usefixtures("require_interfaces")

CLIENT = Path(__file__).with_name("hostile_client.py")


def _client_module() -> object:
    import importlib.util

    spec = importlib.util.spec_from_file_location("cdw_hostile_client", CLIENT)
    assert spec is not None
    assert spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_hostile_claims_and_oversized_messages_are_refused_counted_and_bounded(
    ros_env: dict[str, str], builtin_meshes: Path, tmp_path: Path
) -> None:
    from twin.claims import ClaimLimits
    from twin.ros_node import MAX_FAULT_EVENTS_PER_S

    client = _client_module()
    out = tmp_path / "run"
    args = [
        *("--cell", "two_pandas", "--dataset", str(builtin_meshes), "--out", str(out)),
        *("--mode", "realtime", "--duration", "6", "--speed", "0.4", "--objects", "1"),
    ]
    twin = start_twin_node(ros_env, args)
    hostile = start(ros_env, str(CLIENT), str(tmp_path / "client.json"))
    assert finish(hostile, 120.0) == 0
    assert finish(twin, 120.0) == 0, twin.stderr.read().decode()[-3000:] if twin.stderr else ""
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["complete"] is True
    rejected = summary["rejected_commands"]
    limit = ClaimLimits().max_per_station
    assert set(rejected) == {"bad_claim", "claims_full", "oversized"}
    assert rejected["claims_full"] == client.VALID_TRACKS - limit  # type: ignore[attr-defined]
    assert rejected["oversized"] == 3
    # the paced bad claims all, and of the flood at least enough to pass the event budget
    bad = len(client.BAD_CLAIMS)  # type: ignore[attr-defined]
    assert bad + MAX_FAULT_EVENTS_PER_S < rejected["bad_claim"] <= bad + client.FLOOD  # type: ignore[attr-defined]
    # the board: never more than a station's bound, only well-formed claims, named as its topic
    boards = json.loads((tmp_path / "client.json").read_text(encoding="utf-8"))["boards"]
    assert boards, "no board was relayed"
    assert max(len(b) for b in boards) == limit
    entries = [entry for board in boards for entry in board]
    assert {station for station, *_ in entries} == {"upstream"}
    assert all(math.isfinite(x) and math.isfinite(vx) for *_, x, vx, _r in entries)
    assert all(0.0 < radius <= 1.0 for *_, radius in entries)
    # every refusal counted, but the event log takes at most its budget per topic and second
    events = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    faults = [e for e in events if e["type"] == "fault"]
    per_second = Counter((e["data"]["detail"].split(":")[0], int(e["time_s"])) for e in faults)
    assert max(per_second.values()) <= MAX_FAULT_EVENTS_PER_S
    assert summary["unlogged_rejections"] == sum(rejected.values()) - len(faults) > 0
    oversized = [e["data"]["detail"] for e in faults if e["data"]["kind"] == "oversized"]
    assert any(d.startswith("/s1/arm_controller/joint_trajectory: rejected") for d in oversized)
    assert any(d.startswith("/sorting/priorities: rejected") for d in oversized)
    assert all(len(e["data"]["detail"]) < 400 for e in faults)  # a client's string is cut
