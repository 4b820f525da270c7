"""The lockstep protocol's bookkeeping (:mod:`twin.lockstep`), without ROS."""

from __future__ import annotations

from interfaces.contract import BELT_STATE, CLAIMS, DETECTIONS, JOINT_STATES
from twin.lockstep import MAX_ACKS_AHEAD, RESYNC_WAIT_S, AckBook, Settled, TickCounter

PATIENCE = {"ack_timeout_s": 2.0, "start_timeout_s": 60.0}


def test_a_tick_is_ready_once_its_ack_and_every_command_it_announces_arrived() -> None:
    book = AckBook()
    assert not book.tick_ready(3)
    assert book.take_ack(3, 2, 4, current_tick=3) == ""
    assert not book.tick_ready(3)  # two commands announced, none arrived
    book.command_received()
    assert not book.tick_ready(3)
    book.command_received()
    assert book.tick_ready(3)
    book.consume_tick(3)
    assert book.pending == 0
    assert book.acks == {}


def test_consuming_a_tick_forgets_older_acks_and_never_counts_below_zero() -> None:
    book = AckBook()
    for tick in (1, 2, 3):
        book.take_ack(tick, 1, tick + 1, current_tick=tick)
    book.consume_tick(3)  # one command announced, none received
    assert book.pending == 0
    assert book.acks == {}
    assert book.last_ack_tick == 3


def test_an_ack_too_far_ahead_is_refused_and_names_both_ticks() -> None:
    book = AckBook()
    detail = book.take_ack(MAX_ACKS_AHEAD + 6, 0, 0, current_tick=5)
    assert detail == f"tick {MAX_ACKS_AHEAD + 6} while the twin is at tick 5"
    assert book.acks == {}
    assert book.take_ack(MAX_ACKS_AHEAD + 5, 0, 0, current_tick=5) == ""


def test_patience_skips_ticks_before_the_announced_next_control_tick() -> None:
    book = AckBook()
    assert book.patience_s(0, **PATIENCE) == 60.0  # the first tick: the start timeout
    book.take_ack(0, 0, 5, current_tick=0)
    book.consume_tick(0)
    for tick in range(1, 5):
        assert book.patience_s(tick, **PATIENCE) is None
    assert book.patience_s(5, **PATIENCE) == 2.0


def test_a_missed_tick_loses_the_controller_and_a_resumed_one_is_waited_for() -> None:
    book = AckBook()
    book.take_ack(0, 0, 1, current_tick=0)
    assert book.settle(0, time_s=0.0) == Settled(ready=True)
    book.command_received()  # a command whose ack never comes
    lost = book.settle(1, time_s=0.5)
    assert lost.timed_out
    assert not lost.ready
    assert not book.alive
    assert book.lost_at_s == 0.5
    assert book.pending == 0  # what was received counts as applied
    assert book.patience_s(2, **PATIENCE) is None  # lost and silent: not waited for
    book.take_ack(7, 0, 8, current_tick=7)  # a restarted controller acknowledges again
    assert book.patience_s(7, **PATIENCE) == RESYNC_WAIT_S
    resumed = book.settle(7, time_s=2.0)
    assert resumed.ready
    assert resumed.resumed_after_s == 1.5
    assert book.alive
    assert book.lost_at_s is None


def test_a_controller_missing_at_the_start_is_lost_from_time_zero() -> None:
    book = AckBook()
    assert book.start(matched=False)
    assert book.lost_at_s == 0.0
    assert not AckBook().start(matched=True)


def test_the_tick_counter_announces_counts_since_the_last_tick_and_newest_stamps() -> None:
    ticks = TickCounter()
    ticks.count(JOINT_STATES.name, 100)
    ticks.count(BELT_STATE.name, 90)
    ticks.count(JOINT_STATES.name, 80)
    first = ticks.take(1, 0, 100)
    assert (first.tick, first.n_joint_states, first.n_belt_states, first.n_detections) == (
        1,
        2,
        1,
        0,
    )
    assert first.last_joint_state_ns == 100
    assert first.last_detections_ns == -1
    ticks.count(DETECTIONS.name, 95)
    second = ticks.take(2, 0, 200)
    assert (second.n_joint_states, second.n_detections, second.n_claims) == (0, 1, 0)
    assert second.last_joint_state_ns == 100  # the newest stamp stays announced
    assert second.last_claims_ns == -1
    ticks.count(CLAIMS.name, 150)
    assert ticks.take(3, 0, 300).n_claims == 1
