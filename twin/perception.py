"""Simulated perception: what a camera-based detector over the belt would report.

Every ``1 / rate_hz`` seconds a frame is captured from the ground truth: objects lying on the belt
inside the camera's field of view (an x interval over the belt's width: the cell's
:class:`interfaces.cell.CameraSpec`, where the camera is; the error model here is the
scenario's). Each detection carries
the footprint centroid (its z at the object's underside: the belt surface, or the top of the
object it lies on), the long-axis yaw (modulo pi), length, width and height as seen from above
(``twin.top_view``: an object that has tipped over shows a side), with Gaussian position noise (a
``position_outlier_rate`` share of it from a wider Gaussian, drawn from its own stream) and yaw
noise, a per-object drop probability and a misclassification probability (a uniformly chosen
other class). With a ``suction_points`` finder (:mod:`twin.suction_point`) each detection also
carries the suction point of the face turned up, shifted by the same position noise, and its
radius and the tilt of that face from level. The frame is released ``latency_s`` after capture,
stamped with its capture time.
``PerceptionConfig.zero_noise()`` gives the exact ground truth with no delay, drop or confusion.
All randomness comes from the generator passed in (the scenario's seed tree).

Confidence, as a real detector's: higher on average when the class is right than when it is
wrong. A correct class's confidence is drawn from Beta(k m, k (1 - m)) with mean
``m = confidence_correct_mean`` (0.9) and concentration ``k = confidence_concentration`` (20);
a misclassified one's from the same with ``m = confidence_wrong_mean`` (0.55). A mean of 1 gives
exactly 1 (the zero-noise camera's). The draws come from a child generator spawned from the one
passed in (``Generator.spawn``), one draw per reported detection, so positions, drops and
classes of a seed do not depend on the confidence model.

Detection dropout (an injected fault): a frame captured inside a ``[start_s, end_s)`` dropout
window is never released. Its random numbers are drawn all the same, so the frames outside the
windows are exactly those of the same seed without dropout.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

import numpy as np

from interfaces.cell import CameraSpec
from interfaces.detections import Detection, DetectionFrame, wrap_half_pi
from twin.perception_config import PerceptionConfig

if TYPE_CHECKING:
    from twin.ground_truth import GroundTruth


class Perception:
    """Captures frames on a fixed step grid and releases them after the latency.

    ``classes`` are the names a misclassification chooses among; ``camera`` is the field of view
    (default: the reference cell's).
    """

    def __init__(
        self,
        config: PerceptionConfig,
        classes: Iterable[str],
        surface_z_m: float,
        dt_s: float,
        rng: np.random.Generator,
        *,
        camera: CameraSpec | None = None,
        dropout_windows_s: Iterable[tuple[float, float]] = (),
        suction_points: Callable[[GroundTruth], tuple[tuple[float, float, float], float, float]]
        | None = None,
    ) -> None:
        self.config = config
        self.camera = camera if camera is not None else CameraSpec()
        self.dropout_windows_s = tuple((float(a), float(b)) for a, b in dropout_windows_s)
        self.dropped_frames = 0
        self.classes = tuple(classes)
        self.surface_z_m = surface_z_m
        self.every_n_steps = max(1, round(1.0 / (config.rate_hz * dt_s)))
        self.rng = rng
        (self._confidence_rng,) = rng.spawn(1)  # its own stream: the others stay as they were
        # the outliers' own stream too, spawned only when there are any (same seeds, same frames)
        self._outlier_rng = rng.spawn(1)[0] if config.position_outlier_rate > 0 else None
        self._queue: deque[DetectionFrame] = deque()
        self._suction_points = suction_points

    def capture_due(self, step: int) -> bool:
        """Whether a frame is captured at this step."""
        return step % self.every_n_steps == 0

    def in_dropout(self, time_s: float) -> bool:
        """Whether the camera delivers nothing at ``time_s`` (inside a dropout window)."""
        return any(a <= time_s < b for a, b in self.dropout_windows_s)

    def capture(self, time_s: float, objects: Iterable[GroundTruth]) -> DetectionFrame:
        """Take a frame from the ground truth and queue it for release.

        Inside a dropout window the frame is returned but not queued (counted in
        ``dropped_frames``): it is never released.
        """
        cfg = self.config
        fov_min_x, fov_max_x = self.camera.fov_min_x_m, self.camera.fov_max_x_m
        detections = []
        for obj in objects:
            x, y, _ = obj.position_m
            if not obj.on_belt or not fov_min_x <= x <= fov_max_x:
                continue
            # draw every random number for every candidate so streams stay aligned
            drop, confuse, pick = self.rng.random(3)
            noise = self.rng.standard_normal(3)
            if drop < cfg.drop_rate:
                continue
            name, seen = obj.class_name, obj.top_view
            if confuse < cfg.misclassification_rate and len(self.classes) > 1:
                others = [c for c in self.classes if c != name]
                name = others[int(pick * len(others))]
            confidence = cfg.draw_confidence(self._confidence_rng, correct=name == obj.class_name)
            dx_m, dy_m = self._position_noise(float(noise[0]), float(noise[1]))
            suction_m, suction_radius_m = (math.nan, math.nan, math.nan), math.nan
            suction_tilt_rad = math.nan
            if self._suction_points is not None:
                (sx, sy, sz), suction_radius_m, suction_tilt_rad = self._suction_points(obj)
                suction_m = (sx + dx_m, sy + dy_m, sz)
            detections.append(
                Detection(
                    class_name=name,
                    confidence=confidence,
                    x_m=x + dx_m,
                    y_m=y + dy_m,
                    z_m=max(self.surface_z_m, obj.position_m[2] - seen.below_m),
                    yaw_rad=wrap_half_pi(seen.yaw_rad + cfg.yaw_noise_rad * float(noise[2])),
                    length_m=seen.length_m,
                    width_m=seen.width_m,
                    height_m=seen.height_m,
                    suction_point_m=suction_m,
                    suction_radius_m=suction_radius_m,
                    suction_tilt_rad=suction_tilt_rad,
                )
            )
        frame = DetectionFrame(
            capture_time_s=time_s,
            release_time_s=time_s + cfg.latency_s,
            detections=tuple(detections),
        )
        if self.in_dropout(time_s):
            self.dropped_frames += 1
        else:
            self._queue.append(frame)
        return frame

    def _position_noise(self, n_x: float, n_y: float) -> tuple[float, float]:
        """The (x, y) error of one detection from its two standard normal draws: scaled by
        ``position_noise_m``, or for an outlier (``position_outlier_rate``, its own stream, one
        uniform per candidate) by ``position_outlier_noise_m``."""
        cfg = self.config
        std_m = cfg.position_noise_m
        if self._outlier_rng is not None and self._outlier_rng.random() < cfg.position_outlier_rate:
            std_m = cfg.position_outlier_noise_m
        return std_m * n_x, std_m * n_y

    def released(self, time_s: float) -> list[DetectionFrame]:
        """Frames whose latency has elapsed by ``time_s``, oldest first."""
        out = []
        while self._queue and self._queue[0].release_time_s <= time_s + 1e-9:
            out.append(self._queue.popleft())
        return out
