"""Lockstep message attribution by stamp (pure; the ROS node uses it unchanged)."""

from __future__ import annotations

import pytest

from control.inbox import StampedInbox

TOPICS = ("/joint_states", "/conveyor/state", "/objects/detections")
DT_NS = 4_166_667  # one 240 Hz step, rounded as the twin stamps it


class Cell:
    """What the twin publishes: a joint state every tick, a belt state every 4th, a detection
    frame every 8th (stamped 7 ticks earlier, its capture time), then the tick with the newest
    stamp per topic."""

    def __init__(self) -> None:
        self.last_ns = [-1, -1, -1]

    def tick(self, k: int) -> tuple[list[tuple[str, int]], tuple[int, int, int]]:
        t_ns = k * DT_NS
        msgs = [("/joint_states", t_ns)]
        if k % 4 == 0:
            msgs.append(("/conveyor/state", t_ns))
        if k % 8 == 7:
            msgs.append(("/objects/detections", t_ns - 7 * DT_NS))
        for topic, stamp in msgs:
            i = TOPICS.index(topic)
            self.last_ns[i] = max(self.last_ns[i], stamp)
        return msgs, (self.last_ns[0], self.last_ns[1], self.last_ns[2])


def test_each_tick_gets_exactly_its_own_messages_whatever_the_arrival_order() -> None:
    cell = Cell()
    inbox: StampedInbox[tuple[int, str]] = StampedInbox(TOPICS)
    ticks = [cell.tick(k) for k in range(40)]
    # every message of tick k+1 arrives before tick k is handled (DDS orders topics apart)
    for k, (msgs, _) in enumerate(ticks):
        for topic, stamp in msgs:
            inbox.add(topic, stamp, (k, topic))
        if k == 0:
            continue
        prev_msgs, prev_last = ticks[k - 1]
        assert inbox.complete(prev_last)
        got = [m for topic in TOPICS for m in inbox.take(topic, prev_last[TOPICS.index(topic)])]
        assert sorted(got) == sorted((k - 1, topic) for topic, _ in prev_msgs)
    assert inbox.complete(ticks[-1][1])


def test_a_tick_waits_for_a_message_still_in_flight() -> None:
    cell = Cell()
    inbox: StampedInbox[str] = StampedInbox(TOPICS)
    for k in range(8):
        msgs, last = cell.tick(k)
        for topic, stamp in msgs:
            if topic != "/objects/detections":
                inbox.add(topic, stamp, topic)
    assert last[2] >= 0
    assert not inbox.complete(last)  # the frame of tick 7 has not arrived
    inbox.add("/objects/detections", last[2], "frame")
    assert inbox.complete(last)


def test_a_controller_that_starts_late_finds_its_place_in_the_streams() -> None:
    """A restart: the new controller hears the streams from some tick on, each topic from a
    different message, and messages of later ticks before the tick it handles first. Counting
    from its own start made it wait for messages that never came; stamps place each one."""
    cell = Cell()
    ticks = [cell.tick(k) for k in range(200)]
    inbox: StampedInbox[int] = StampedInbox(TOPICS)
    joined = {"/joint_states": 101, "/conveyor/state": 98, "/objects/detections": 104}
    for k in range(100, 120):  # messages through tick 119 arrive before tick 100 is handled
        for topic, stamp in ticks[k][0]:
            if k >= joined[topic]:
                inbox.add(topic, stamp, k)
    for k in range(100, 120):
        last = ticks[k][1]
        assert inbox.complete(last), k
        got = [m for t in TOPICS for m in inbox.take(t, last[TOPICS.index(t)])]
        # exactly the messages of tick k this controller heard (tick 100's joint state and
        # tick 103's frame were sent before it listened)
        assert got == [k for topic, _ in ticks[k][0] if k >= joined[topic]], k
    assert not inbox.complete(ticks[120][1])  # tick 120's messages are not here yet


def test_nothing_published_yet_needs_nothing() -> None:
    inbox: StampedInbox[str] = StampedInbox(TOPICS)
    assert inbox.complete((0, -1, -1)) is False
    inbox.add("/joint_states", 0, "q")
    assert inbox.complete((0, -1, -1))
    assert inbox.take("/conveyor/state", -1) == []
    assert inbox.take("/joint_states", 0) == ["q"]


def test_a_stale_stamp_waits_behind_the_message_ahead_of_it() -> None:
    inbox: StampedInbox[str] = StampedInbox(TOPICS)
    inbox.add("/objects/detections", 50, "new")
    inbox.add("/objects/detections", 10, "stale")
    assert inbox.take("/objects/detections", 20) == []
    assert inbox.take("/objects/detections", 50) == ["new", "stale"]
    assert inbox.take("/objects/detections") == []


def test_bad_use_names_what_was_wrong() -> None:
    with pytest.raises(ValueError, match="repeat"):
        StampedInbox(["/a", "/a"])
    inbox: StampedInbox[str] = StampedInbox(TOPICS)
    with pytest.raises(KeyError, match="/tcp_pose"):
        inbox.add("/tcp_pose", 0, "x")
    with pytest.raises(ValueError, match="2 stamps for 3 topics"):
        inbox.complete((0, 0))
