"""The twin's summary of an episode (``summary.json``,
:class:`interfaces.run_records.EpisodeSummary`): what the twin and its endpoint measured when
the episode ended.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from interfaces.run_records import EpisodeSummary, StationSummary, TrackingSummary

if TYPE_CHECKING:
    from twin.ros_node import TwinEndpoint
    from twin.sim import Twin


def final_state(twin: Twin) -> dict[str, object]:
    """Exact end state (for determinism checks): every station's arm joints (in station order)
    and every object's pose."""
    obs = twin.observe()
    return {
        "step": obs.step,
        "joint_positions": [q for arm in obs.arms for q in arm.joint_positions],
        "belt_position_m": obs.belt.belt_position_m,
        "objects": {str(o.id): [*o.position_m, *o.orientation_xyzw] for o in obs.objects},
    }


def tracking_block(twin: Twin, station: str | None) -> TrackingSummary:
    """The tracking block of the line (``station`` None) or a station: the metric table's
    summary of every finished pursuit's time to 4 mm."""
    from interfaces.metrics import tracking_summary

    return tracking_summary([r.time_to_threshold_s for r in twin.tracking_results(station)])


def episode_summary(
    twin: Twin,
    endpoint: TwinEndpoint,
    *,
    mode: str,
    transport: str,
    wall_s: float,
    match_wall_s: float,
    stopped_by: str | None,
) -> EpisodeSummary:
    """The summary of the episode that just ended (``stopped_by``: the signal that stopped it
    early, None when it ran to its end): settings, timing, the event scores of the line and of
    each station, tracking, the endpoint's counters and latency, the final state and, with a
    camera, the perception scores (non-finite ones as None)."""
    scenario = twin.scenario
    perception = twin.perception_summary()
    return EpisodeSummary(
        scenario=scenario.name,
        seed=scenario.seed,
        mode=mode,
        belt_speed_mps=scenario.system.belt_speed_mps,
        complete=stopped_by is None,
        sim_seconds=twin.time_s,
        wall_seconds=wall_s,
        match_wall_seconds=match_wall_s,
        transport=transport,
        real_time_factor=twin.time_s / wall_s if wall_s > 0 else 0.0,
        cell=twin.cell.name,
        scores=twin.scores(),
        stations={
            link.name: StationSummary(
                scores=twin.scores(link.name),
                tracking=tracking_block(twin, link.name),
                latency=link.telemetry.latency(),
            )
            for link in endpoint.links
        },
        landing_in_bins=tuple(twin.landing_in_bins()),
        tracking=tracking_block(twin, None),
        published=dict(endpoint.counters.published),
        received_commands=endpoint.counters.received_commands,
        rejected_commands=dict(endpoint.counters.rejected),
        unlogged_rejections=endpoint.counters.unlogged,
        lockstep_timeouts=endpoint.counters.lockstep_timeouts,
        priorities=tuple(endpoint.priorities),
        final_state=final_state(twin),
        latency=endpoint.telemetry.latency(),
        step_rate_hz_mean=endpoint.telemetry.step_rate_hz_mean(),
        perception=None
        if perception is None
        else {k: (v if math.isfinite(v) else None) for k, v in sorted(perception.items())},
        stopped_by=stopped_by,
    )
