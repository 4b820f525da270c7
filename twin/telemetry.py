"""Telemetry of a twin episode: round-trip latency, step rate, belt setpoint against speed.

Pure bookkeeping, free of ROS; :class:`twin.ros_node.TwinNode` feeds a :class:`TelemetryRecorder`
and ``cdw-twin twin-node --out DIR`` writes it as ``DIR/telemetry.json`` when the episode ends.

Round-trip latency (RTT), closed loop: the controller stamps each
``/arm_controller/joint_trajectory`` with the sim time of the state it responded to (realtime:
the ``/joint_states`` stamp; lockstep: the tick stamp, equal to that step's joint state stamp).
The twin remembers when it published the joint state of each stamp (a ring of the last
:data:`RING_SIZE` stamps) and, when a trajectory with stamp ``s`` arrives, records
``rtt = wall(trajectory received) - wall(joint state s published)``. Trajectories whose stamp is
unknown (evicted from the ring, or never published) are counted, not measured.

``telemetry.json`` (every wall time in seconds from the first recorded event, perf counter)::

    {
      "version": 1,
      "rtt": {"wall_s": [...], "sim_s": [...], "rtt_ms": [...]},
      "step_rate": {"wall_s": [...], "steps_per_s": [...], "rtf": [...]},
      "belt": {"sim_s": [...], "setpoint_mps": [...], "speed_mps": [...]},
      "summary": {"latency": {... TelemetryRecorder.latency() ...}, "step_rate_hz_mean": ...}
    }

``step_rate`` has one row per wall-clock second (``wall_s`` is the window's end; ``rtf`` is sim
seconds per wall second in that window) and a last row for the unfinished window at the end, so
an episode shorter than a window still has a rate; ``belt`` is sampled every
:data:`BELT_PERIOD_S` of sim time.
"""

from __future__ import annotations

import json
import math

import numpy as np

from interfaces.dataclass_io import to_data
from interfaces.run_records import LatencySummary

RING_SIZE = 1024
"""Publish times kept for matching (about 4 s of joint states at 240 Hz)."""

BELT_PERIOD_S = 0.1
"""Sim seconds between belt samples (10 Hz)."""

STEP_WINDOW_S = 1.0
"""Wall seconds per step-rate row."""

_KEY_SCALE = 1e6


def stamp_key(stamp_s: float) -> int:
    """The matching key of a stamp: whole microseconds (stamps are 1/240 s apart)."""
    return round(stamp_s * _KEY_SCALE)


def percentile_ms(values: list[float], q: float) -> float | None:
    """The ``q``-th percentile (linear interpolation) of ``values``; None when empty."""
    return float(np.percentile(values, q)) if values else None


class TelemetryRecorder:
    """Collects RTT samples, step-rate windows and belt samples of one episode.

    All times are passed in (``wall_s`` from ``time.perf_counter()``, ``sim_s`` the twin's
    time), so the class is deterministic and cheap: each call is a few dict and list operations.
    """

    def __init__(
        self,
        *,
        ring_size: int = RING_SIZE,
        belt_period_s: float = BELT_PERIOD_S,
        step_window_s: float = STEP_WINDOW_S,
    ) -> None:
        if ring_size < 1:
            msg = f"ring_size must be at least 1, got {ring_size}"
            raise ValueError(msg)
        self.ring_size = ring_size
        self.belt_period_s = belt_period_s
        self.step_window_s = step_window_s
        self._published: dict[int, float] = {}
        self._wall0: float | None = None
        self.rtt_wall_s: list[float] = []
        self.rtt_sim_s: list[float] = []
        self.rtt_ms: list[float] = []
        self.unmatched_commands = 0
        self.rate_wall_s: list[float] = []
        self.rate_steps_per_s: list[float] = []
        self.rate_rtf: list[float] = []
        self._window_wall_s: float | None = None
        self._window_sim_s = 0.0
        self._window_steps = 0
        self._last_wall_s = 0.0
        self._last_sim_s = 0.0
        self.steps = 0
        self.belt_sim_s: list[float] = []
        self.belt_setpoint_mps: list[float] = []
        self.belt_speed_mps: list[float] = []
        self._next_belt_s = -math.inf

    def _origin(self, wall_s: float) -> float:
        if self._wall0 is None:
            self._wall0 = wall_s
        return self._wall0

    # -- latency ----------------------------------------------------------------------------
    def on_state_published(self, stamp_s: float, wall_s: float) -> None:
        """The joint state stamped ``stamp_s`` was published at ``wall_s``."""
        self._origin(wall_s)
        published = self._published
        published[stamp_key(stamp_s)] = wall_s
        if len(published) > self.ring_size:
            del published[next(iter(published))]

    def on_command(self, stamp_s: float, wall_s: float) -> float | None:
        """A trajectory stamped ``stamp_s`` arrived at ``wall_s``; returns its RTT in ms.

        None (and counted in ``unmatched_commands``) when no state with that stamp is known.
        """
        sent = self._published.get(stamp_key(stamp_s))
        if sent is None:
            self.unmatched_commands += 1
            return None
        rtt_ms = 1e3 * (wall_s - sent)
        self.rtt_wall_s.append(wall_s - self._origin(wall_s))
        self.rtt_sim_s.append(stamp_s)
        self.rtt_ms.append(rtt_ms)
        return rtt_ms

    # -- step rate --------------------------------------------------------------------------
    def on_step(self, sim_s: float, wall_s: float) -> None:
        """One physics step finished at ``wall_s``, the twin now at ``sim_s``."""
        wall0 = self._origin(wall_s)
        self.steps += 1
        self._last_wall_s, self._last_sim_s = wall_s, sim_s
        if self._window_wall_s is None:
            self._window_wall_s, self._window_sim_s, self._window_steps = wall_s, sim_s, 0
            return
        self._window_steps += 1
        elapsed = wall_s - self._window_wall_s
        if elapsed >= self.step_window_s:
            self.rate_wall_s.append(wall_s - wall0)
            self.rate_steps_per_s.append(self._window_steps / elapsed)
            self.rate_rtf.append((sim_s - self._window_sim_s) / elapsed)
            self._window_wall_s, self._window_sim_s, self._window_steps = wall_s, sim_s, 0

    def _rate_rows(self) -> tuple[list[float], list[float], list[float]]:
        """The closed windows plus the unfinished one at the end (when it holds a step)."""
        wall, steps, rtf = list(self.rate_wall_s), list(self.rate_steps_per_s), list(self.rate_rtf)
        start = self._window_wall_s
        if start is not None and self._window_steps > 0 and self._last_wall_s > start:
            elapsed = self._last_wall_s - start
            wall.append(self._last_wall_s - self._origin(self._last_wall_s))
            steps.append(self._window_steps / elapsed)
            rtf.append((self._last_sim_s - self._window_sim_s) / elapsed)
        return wall, steps, rtf

    # -- belt -------------------------------------------------------------------------------
    def on_belt(self, sim_s: float, setpoint_mps: float, speed_mps: float) -> None:
        """A belt state at ``sim_s``; kept every ``belt_period_s`` of sim time."""
        if sim_s + 1e-9 < self._next_belt_s:
            return
        self._next_belt_s = sim_s + self.belt_period_s
        self.belt_sim_s.append(sim_s)
        self.belt_setpoint_mps.append(setpoint_mps)
        self.belt_speed_mps.append(speed_mps)

    # -- output -----------------------------------------------------------------------------
    def latency(self) -> LatencySummary:
        """The round-trip latency block (ms) of the episode's ``summary.json``."""
        rtt = self.rtt_ms
        return LatencySummary(
            rtt_ms_p50=percentile_ms(rtt, 50),
            rtt_ms_p99=percentile_ms(rtt, 99),
            rtt_ms_mean=float(np.mean(rtt)) if rtt else None,
            samples=len(rtt),
            unmatched_commands=self.unmatched_commands,
        )

    def step_rate_hz_mean(self) -> float | None:
        """The mean step rate over the episode's windows (None before the first)."""
        rates = self._rate_rows()[1]
        return float(np.mean(rates)) if rates else None

    def to_json(self) -> str:
        """The whole record as ``telemetry.json`` text (layout in the module docstring)."""
        rate_wall, rate_steps, rate_rtf = self._rate_rows()
        data = {
            "version": 1,
            "rtt": {
                "wall_s": [round(v, 6) for v in self.rtt_wall_s],
                "sim_s": [round(v, 6) for v in self.rtt_sim_s],
                "rtt_ms": [round(v, 4) for v in self.rtt_ms],
            },
            "step_rate": {
                "wall_s": [round(v, 4) for v in rate_wall],
                "steps_per_s": [round(v, 3) for v in rate_steps],
                "rtf": [round(v, 5) for v in rate_rtf],
            },
            "belt": {
                "sim_s": [round(v, 6) for v in self.belt_sim_s],
                "setpoint_mps": [round(v, 6) for v in self.belt_setpoint_mps],
                "speed_mps": [round(v, 6) for v in self.belt_speed_mps],
            },
            "summary": {
                "latency": to_data(self.latency()),
                "step_rate_hz_mean": self.step_rate_hz_mean(),
            },
        }
        return json.dumps(data, separators=(",", ":")) + "\n"


__all__ = ["BELT_PERIOD_S", "RING_SIZE", "TelemetryRecorder", "percentile_ms", "stamp_key"]
