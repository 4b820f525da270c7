"""The oracle's error model fitted to what a camera and its detector measurably get wrong.

The oracle (:class:`twin.perception.Perception`) reports every piece in view with Gaussian
position and yaw noise, a drop rate and a misclassification rate, and (optionally) a share of
position outliers drawn with a wider Gaussian: a detector's centroid is mostly a few millimetres
off, and now and then centimetres (fragments, merges, a piece half hidden). This module turns the
camera's released detection frames, set against the ground truth at each exposure, into those
parameters, so that an oracle run stands for the camera's perception with its figures traceable
to a measurement (:class:`OracleFit`, ``fitted_from``).

Matching, per frame: the truth pieces are those on the belt, not held, whose centre lies in the
cameras' view by at least half the piece's length (a piece cut by the image's edge is one the
camera leaves out on purpose); each detection goes to the nearest unmatched piece within
:data:`MATCH_GATE_M`, nearest pairs first. What the fit reads from them:

- ``drop_rate``: 1 - matched / truth pieces in view;
- ``misclassification_rate``: wrong classes / matched;
- ``position_noise_m``, ``position_outlier_rate``, ``position_outlier_noise_m``: the per-axis
  standard deviations and mixing share of a two-component zero-mean Gaussian mixture fitted to
  the matched (dx, dy) by expectation-maximisation (:func:`fit_position_mixture`);
- ``yaw_noise_rad``: 1.4826 times the median absolute yaw error (a robust standard deviation),
  over elongated pieces only (:data:`YAW_ELONGATION`: a square's axis means nothing);
- what the oracle does not model is counted, not fitted: detections matching no piece (spurious
  fragments) per frame.

Pure logic: no PyBullet, no renderer (the command that runs the twin is
:mod:`experiments.oracle_fit`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from interfaces.detections import Detection, wrap_half_pi

__all__ = [
    "MATCH_GATE_M",
    "YAW_ELONGATION",
    "FitSample",
    "FrameMatch",
    "OracleFit",
    "PositionMixture",
    "TruthPiece",
    "fit_oracle",
    "fit_position_mixture",
    "match_frame",
]

MATCH_GATE_M = 0.08
"""Farthest a detection's centroid may lie from a piece's centre to count as that piece (m)."""

YAW_ELONGATION = 1.5
"""A piece's yaw error counts only when its top face is at least this many times longer than
wide."""

_MAD_TO_STD = 1.4826


@dataclass(frozen=True, kw_only=True)
class TruthPiece:
    """One piece the camera should have seen at an exposure (world frame)."""

    object_id: int
    class_name: str
    x_m: float
    y_m: float
    yaw_rad: float
    length_m: float
    width_m: float


@dataclass(frozen=True, kw_only=True)
class FrameMatch:
    """One frame's detections set against its truth pieces."""

    pairs: tuple[tuple[Detection, TruthPiece], ...]
    missed: tuple[TruthPiece, ...]
    spurious: tuple[Detection, ...]


def match_frame(
    detections: Sequence[Detection], truth: Sequence[TruthPiece], gate_m: float = MATCH_GATE_M
) -> FrameMatch:
    """Pair ``detections`` with ``truth`` one to one, nearest pairs first, within ``gate_m``."""
    candidates = sorted(
        (math.hypot(d.x_m - t.x_m, d.y_m - t.y_m), i, j)
        for i, d in enumerate(detections)
        for j, t in enumerate(truth)
    )
    used_d: set[int] = set()
    used_t: set[int] = set()
    pairs = []
    for distance_m, i, j in candidates:
        if distance_m > gate_m:
            break
        if i in used_d or j in used_t:
            continue
        used_d.add(i)
        used_t.add(j)
        pairs.append((detections[i], truth[j]))
    return FrameMatch(
        pairs=tuple(pairs),
        missed=tuple(t for j, t in enumerate(truth) if j not in used_t),
        spurious=tuple(d for i, d in enumerate(detections) if i not in used_d),
    )


@dataclass(frozen=True, kw_only=True)
class FitSample:
    """What the fit reads, pooled over frames (see the module)."""

    frames: int
    truth_in_view: int
    dx_m: tuple[float, ...]
    dy_m: tuple[float, ...]
    yaw_error_rad: tuple[float, ...]
    class_wrong: int
    spurious: int

    @property
    def matched(self) -> int:
        """Matched pairs."""
        return len(self.dx_m)

    @classmethod
    def of(cls, matches: Iterable[FrameMatch]) -> FitSample:
        """Pool frame matches."""
        frames = truth = wrong = spurious = 0
        dx: list[float] = []
        dy: list[float] = []
        yaw: list[float] = []
        for match in matches:
            frames += 1
            truth += len(match.pairs) + len(match.missed)
            spurious += len(match.spurious)
            for det, piece in match.pairs:
                dx.append(det.x_m - piece.x_m)
                dy.append(det.y_m - piece.y_m)
                wrong += det.class_name != piece.class_name
                if piece.length_m >= YAW_ELONGATION * piece.width_m:
                    yaw.append(wrap_half_pi(det.yaw_rad - piece.yaw_rad))
        return cls(
            frames=frames,
            truth_in_view=truth,
            dx_m=tuple(dx),
            dy_m=tuple(dy),
            yaw_error_rad=tuple(yaw),
            class_wrong=wrong,
            spurious=spurious,
        )


@dataclass(frozen=True, kw_only=True)
class PositionMixture:
    """Per-axis position errors as ``(1 - outlier_rate) N(0, inlier_std_m^2) +
    outlier_rate N(0, outlier_std_m^2)`` (both axes alike)."""

    inlier_std_m: float
    outlier_rate: float
    outlier_std_m: float


def _normal_2d(r2: np.ndarray, std_m: float) -> np.ndarray:
    var = std_m * std_m
    return np.exp(-0.5 * r2 / var) / (2.0 * math.pi * var)


def fit_position_mixture(
    dx_m: Sequence[float], dy_m: Sequence[float], *, iterations: int = 200
) -> PositionMixture:
    """Fit :class:`PositionMixture` to the 2D errors by expectation-maximisation.

    Starts from the median radius (inliers) and the 90th percentile (outliers); a sample too
    small or too tight for two components (fewer than 20 errors, or an outlier component that
    ends up no wider than 1.5 times the inliers) gives a single Gaussian (``outlier_rate`` 0).
    """
    if len(dx_m) != len(dy_m):
        msg = f"dx_m and dy_m differ in length ({len(dx_m)} != {len(dy_m)})"
        raise ValueError(msg)
    r2 = np.asarray(dx_m, dtype=float) ** 2 + np.asarray(dy_m, dtype=float) ** 2
    if r2.size == 0:
        msg = "no matched detections to fit the position noise to"
        raise ValueError(msg)
    single = PositionMixture(
        inlier_std_m=float(math.sqrt(max(r2.mean() / 2.0, 1e-12))),
        outlier_rate=0.0,
        outlier_std_m=0.0,
    )
    if r2.size < 20:
        return single
    radius = np.sqrt(r2)
    # a Rayleigh radius's median is std * sqrt(2 ln 2)
    s_in = max(float(np.median(radius)) / math.sqrt(2.0 * math.log(2.0)), 1e-5)
    s_out = max(float(np.percentile(radius, 95)) / 2.45, 2.0 * s_in)
    share = 0.1
    for _ in range(iterations):
        p_in = (1.0 - share) * _normal_2d(r2, s_in)
        p_out = share * _normal_2d(r2, s_out)
        w = p_out / np.maximum(p_in + p_out, 1e-300)
        share = float(np.clip(w.mean(), 1e-6, 0.5))
        s_in = max(
            math.sqrt(float(((1 - w) * r2).sum()) / (2 * max(float((1 - w).sum()), 1e-9))), 1e-5
        )
        s_out = max(math.sqrt(float((w * r2).sum()) / (2 * max(float(w.sum()), 1e-9))), 1e-5)
    if s_out <= 1.5 * s_in or share <= 1e-4:
        return single
    return PositionMixture(inlier_std_m=s_in, outlier_rate=share, outlier_std_m=s_out)


@dataclass(frozen=True, kw_only=True)
class OracleFit:
    """The fitted oracle parameters (``perception:`` keys of a scenario) and what they rest on."""

    position_noise_m: float
    position_outlier_rate: float
    position_outlier_noise_m: float
    yaw_noise_rad: float
    drop_rate: float
    misclassification_rate: float
    frames: int
    truth_in_view: int
    matched: int
    yaw_samples: int
    spurious_per_frame: float

    def perception_keys(self) -> dict[str, float]:
        """The scenario's ``perception:`` keys this fit sets (rounded for a readable file)."""
        return {
            "position_noise_m": round(self.position_noise_m, 5),
            "position_outlier_rate": round(self.position_outlier_rate, 4),
            "position_outlier_noise_m": round(self.position_outlier_noise_m, 5),
            "yaw_noise_rad": round(self.yaw_noise_rad, 4),
            "drop_rate": round(self.drop_rate, 4),
            "misclassification_rate": round(self.misclassification_rate, 4),
        }


def fit_oracle(sample: FitSample) -> OracleFit:
    """Fit the oracle to ``sample`` (see the module); ValueError when it holds no match."""
    if sample.matched == 0:
        msg = f"no detection matched a piece in {sample.frames} frames: nothing to fit"
        raise ValueError(msg)
    mixture = fit_position_mixture(sample.dx_m, sample.dy_m)
    yaw = np.abs(np.asarray(sample.yaw_error_rad, dtype=float))
    yaw_std = _MAD_TO_STD * float(np.median(yaw)) if yaw.size else 0.0
    return OracleFit(
        position_noise_m=mixture.inlier_std_m,
        position_outlier_rate=mixture.outlier_rate,
        position_outlier_noise_m=mixture.outlier_std_m,
        yaw_noise_rad=yaw_std,
        drop_rate=min(1.0 - sample.matched / sample.truth_in_view, 0.99),
        misclassification_rate=sample.class_wrong / sample.matched,
        frames=sample.frames,
        truth_in_view=sample.truth_in_view,
        matched=sample.matched,
        yaw_samples=int(yaw.size),
        spurious_per_frame=sample.spurious / max(sample.frames, 1),
    )
