"""The waste stream: which object enters the belt where and when.

Each source image's objects enter together, in their recorded layout (metric spacing kept): the
image's upstream edge is placed at ``belt.infeed_x_m`` and its belt frame (origin at the image
centre, +x downstream, +y across) is mapped onto the belt centreline. The next image enters when
the belt has carried the previous one its own length plus ``system.image_gap_m`` downstream: spawn
timing follows the belt speed, whatever it does. Objects whose footprints overlap in the image
(the data is of *stacked* waste) are stacked: each starts just above the objects it overlaps.
Every random choice (order, heights, jitter, friction, restitution) comes from the scenario's seed
tree, object by object, in a fixed order.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from interfaces.cell import BeltSpec
from interfaces.materials import ClassTable, shipped_table
from twin.objects import ImageLayout
from twin.placement import Placement
from twin.scenario import Scenario, SeedTree

_CLEARANCE_M = 0.002


@dataclass(frozen=True)
class ImageBatch:
    """One image's placements, due when the belt has travelled ``trigger_m``."""

    image: str
    trigger_m: float
    placements: tuple[Placement, ...]


def _corners(x: float, y: float, yaw: float, length: float, width: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    half = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]], dtype=float) * [0.5 * length, 0.5 * width]
    corners: np.ndarray = np.array([x, y]) + half @ np.array([[c, s], [-s, c]])
    return corners


def _overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test of two convex quadrilaterals ``(4, 2)``."""
    for poly in (a, b):
        for i in range(4):
            edge = poly[(i + 1) % 4] - poly[i]
            axis = np.array([-edge[1], edge[0]])
            pa, pb = a @ axis, b @ axis
            if pa.max() < pb.min() or pb.max() < pa.min():
                return False
    return True


class Stream:
    """Yields image batches in order; infinite when ``system.repeat_images`` is set.

    ``materials`` is the dataset's class table (the episode's cell carries it): the height,
    friction and restitution ranges of every class the scenario does not give its own
    (``objects.height_ranges_m``, ``physics``).
    """

    def __init__(
        self,
        layouts: tuple[ImageLayout, ...],
        scenario: Scenario,
        belt: BeltSpec,
        seeds: SeedTree,
        materials: ClassTable | None = None,
    ) -> None:
        wanted = set(scenario.objects.images)
        chosen = [lay for lay in layouts if not wanted or lay.image in wanted]
        self._layouts = tuple(chosen)
        self._scenario = scenario
        self._belt = belt
        self._seeds = seeds
        self._materials = materials if materials is not None else shipped_table()
        self._spawned_objects = 0

    def __iter__(self) -> Iterator[ImageBatch]:
        trigger_m = 0.0
        order = list(range(len(self._layouts)))
        cycle = 0
        limit = self._scenario.objects.max_objects
        while order:
            if self._scenario.system.object_order == "shuffled":
                order = [int(i) for i in self._seeds.order.permutation(len(self._layouts))]
            yielded = False
            for index in order:
                if limit is not None and self._spawned_objects >= limit:
                    return
                layout = self._layouts[index]
                batch = self._batch(layout, trigger_m, cycle)
                if not batch.placements:
                    continue
                yield self._prefilled(batch)
                yielded = True
                trigger_m += layout.length_m + self._scenario.system.image_gap_m
            if not self._scenario.system.repeat_images or not yielded:
                return
            cycle += 1

    def _prefilled(self, batch: ImageBatch) -> ImageBatch:
        """Shift a batch due before ``prefill_m`` downstream so it is on the belt at reset."""
        prefill = self._scenario.system.prefill_m
        if prefill <= 0.0:
            return batch
        advance = max(0.0, prefill - batch.trigger_m)
        placements = tuple(
            replace(p, position_m=(p.position_m[0] + advance, p.position_m[1], p.position_m[2]))
            for p in batch.placements
        )
        return replace(batch, trigger_m=max(0.0, batch.trigger_m - prefill), placements=placements)

    def _batch(self, layout: ImageLayout, trigger_m: float, cycle: int) -> ImageBatch:
        objects_cfg = self._scenario.objects
        physics = self._scenario.physics
        rng = self._seeds.objects
        phys_rng = self._seeds.physics
        placements: list[Placement] = []
        footprints: list[tuple[np.ndarray, float]] = []
        x0 = self._belt.infeed_x_m + 0.5 * layout.length_m
        for spec in layout.objects:
            if (
                objects_cfg.max_objects is not None
                and self._spawned_objects >= objects_cfg.max_objects
            ):
                break
            if objects_cfg.classes and spec.class_name not in objects_cfg.classes:
                continue
            if (
                objects_cfg.max_width_m is not None
                and min(spec.width_m, spec.length_m) > objects_cfg.max_width_m
            ):
                continue
            material = self._materials.material(spec.class_name)
            height = spec.height_m
            if objects_cfg.resample_heights:
                lo, hi = objects_cfg.height_ranges_m.get(
                    spec.class_name, (material.height_min_m, material.height_max_m)
                )
                height = float(rng.uniform(lo, hi))
            if objects_cfg.min_height_m is not None and height < objects_cfg.min_height_m:
                continue
            jitter = 0.0
            if objects_cfg.orientation_jitter_rad > 0:
                jitter = float(
                    rng.uniform(
                        -objects_cfg.orientation_jitter_rad, objects_cfg.orientation_jitter_rad
                    )
                )
            f_lo, f_hi = physics.friction.get(spec.class_name, material.friction)
            r_lo, r_hi = physics.restitution.get(spec.class_name, material.restitution)
            friction = float(phys_rng.uniform(f_lo, f_hi))
            restitution = float(phys_rng.uniform(r_lo, r_hi))
            x = x0 + spec.centroid_x_m
            y = self._belt.centre_y_m + spec.centroid_y_m
            quad = _corners(x, y, spec.yaw_rad + jitter, spec.length_m, spec.width_m)
            base_z = self._belt.surface_z_m
            for other, top in footprints:
                if _overlap(quad, other):
                    base_z = max(base_z, top)
            bottom = base_z + _CLEARANCE_M
            footprints.append((quad, bottom + height))
            placements.append(
                Placement(
                    spec=spec,
                    position_m=(x, y, bottom + 0.5 * height),
                    yaw_rad=jitter,
                    height_m=height,
                    friction=friction,
                    restitution=restitution,
                )
            )
            self._spawned_objects += 1
        name = layout.image if cycle == 0 else f"{layout.image}#{cycle}"
        return ImageBatch(image=name, trigger_m=trigger_m, placements=tuple(placements))
