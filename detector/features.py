"""Colour and texture features of every instance of an image, for the classifier.

Per instance (every ``stride``-th pixel, all instances at once with grouped sums): the mean and
standard deviation of CIE L*, a* and b* (a perceptual colour space: grey concrete, red-orange
brick, brown wood and near-black rubber separate along a*, b* and L*), the mean chroma, the mean
local contrast (standard deviation of L* over 3x3), the mean gradient magnitude of L*, the
coherence of the gradient orientations (wood grain runs one way, concrete speckle every way):
``(l1 - l2) / (l1 + l2)`` of the instance's summed structure tensor; then the distribution of
colour within the piece, which a mean hides (a brick's red next to its grey mortar, a concrete
piece's few reddish grains): the mean direction of the hue angle (cosine and sine of
``atan2(b*, a*)``), the mean chroma relative to lightness (``C* / (L* + 5)``: saturation, less
dependent on how brightly the piece is lit than C*), and the 10th, 50th and 90th percentiles of
L*, a* and b* (lower percentiles, on every other sampled pixel). With these the class accuracy
on the shared sample's real photos rose from 0.77 to 0.9 (GT masks, held-out photos).
"""

from __future__ import annotations

import numpy as np

from detector import grouped
from detector.filters import box_mean3

FEATURE_NAMES: tuple[str, ...] = (
    "L_mean",
    "a_mean",
    "b_mean",
    "L_std",
    "a_std",
    "b_std",
    "chroma_mean",
    "contrast_mean",
    "gradient_mean",
    "coherence",
    "hue_cos",
    "hue_sin",
    "chroma_ratio",
    "L_p10",
    "L_p50",
    "L_p90",
    "a_p10",
    "a_p50",
    "a_p90",
    "b_p10",
    "b_p50",
    "b_p90",
)
"""The features, in the order of :func:`instance_features`' columns."""

PERCENTILES: tuple[float, ...] = (10.0, 50.0, 90.0)
"""The percentiles of L*, a* and b* among the features."""

_XYZ_FROM_RGB = np.array(
    [
        [0.4124564, 0.3575761, 0.1804375],
        [0.2126729, 0.7151522, 0.0721750],
        [0.0193339, 0.1191920, 0.9503041],
    ],
    dtype=np.float32,
)
_WHITE_D65 = np.array([0.95047, 1.0, 1.08883], dtype=np.float32)


def _linear_lut() -> np.ndarray:
    """sRGB 8-bit code to linear light, ``(256,) float32``."""
    c = np.arange(256, dtype=np.float64) / 255.0
    out: np.ndarray = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(
        np.float32
    )
    return out


_LINEAR = _linear_lut()


def _lab_f(t: np.ndarray) -> np.ndarray:
    delta = 6.0 / 29.0
    out: np.ndarray = np.where(t > delta**3, np.cbrt(t), t / (3 * delta**2) + 4.0 / 29.0)
    return out


def srgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """CIE L*a*b* (D65) of 8-bit sRGB values, ``(..., 3) uint8`` in, ``(..., 3) float32``
    out."""
    linear = _LINEAR[np.asarray(rgb, dtype=np.uint8)]
    xyz = (linear @ _XYZ_FROM_RGB.T) / _WHITE_D65
    f = _lab_f(xyz)
    lab = np.stack(
        (
            116.0 * f[..., 1] - 16.0,
            500.0 * (f[..., 0] - f[..., 1]),
            200.0 * (f[..., 1] - f[..., 2]),
        ),
        axis=-1,
    )
    out: np.ndarray = lab.astype(np.float32)
    return out


def instance_features(rgb: np.ndarray, labels: np.ndarray, stride: int) -> np.ndarray:
    """Features of instances ``1..n`` of ``labels`` ``(H, W) int`` in ``rgb`` ``(H, W, 3)
    uint8``, ``(n, len(FEATURE_NAMES)) float64`` (columns as :data:`FEATURE_NAMES`; an instance
    without a sampled pixel gets zeros). Colour statistics come from every ``stride``-th pixel
    of the instances; texture from the lightness of the whole sampled image."""
    n = int(labels.max(initial=0))
    if n == 0:
        return np.zeros((0, len(FEATURE_NAMES)))
    sampled = rgb[::stride, ::stride]
    ids = labels[::stride, ::stride]
    lightness: np.ndarray = (116.0 * _lab_f(_LINEAR[sampled] @ _XYZ_FROM_RGB[1]) - 16.0).astype(
        np.float32
    )
    mean3 = box_mean3(lightness)
    contrast = np.sqrt(np.maximum(box_mean3(lightness * lightness) - mean3 * mean3, 0.0))
    gradients = np.gradient(lightness)
    gy, gx = gradients[0], gradients[1]
    rows, cols = np.nonzero(ids)
    owner = ids[rows, cols]
    lab = srgb_to_lab(sampled[rows, cols]).astype(np.float64)
    count = grouped.counts(owner, n)[1:].astype(np.float64)
    safe = np.maximum(count, 1.0)

    def mean_of(values: np.ndarray) -> np.ndarray:
        out: np.ndarray = grouped.sums(owner, values, n)[1:] / safe
        return out

    columns = []
    means = [mean_of(lab[:, c]) for c in range(3)]
    columns.extend(means)
    columns.extend(
        np.sqrt(np.maximum(mean_of(lab[:, c] ** 2) - means[c] ** 2, 0.0)) for c in range(3)
    )
    chroma = np.hypot(lab[:, 1], lab[:, 2])
    columns.append(mean_of(chroma))
    columns.append(mean_of(contrast[rows, cols].astype(np.float64)))
    px, py = gx[rows, cols].astype(np.float64), gy[rows, cols].astype(np.float64)
    columns.append(mean_of(np.hypot(px, py)))
    jxx, jyy, jxy = mean_of(px * px), mean_of(py * py), mean_of(px * py)
    spread = np.sqrt((jxx - jyy) ** 2 + 4.0 * jxy**2)
    columns.append(np.where(jxx + jyy > 0, spread / np.maximum(jxx + jyy, 1e-12), 0.0))
    unit = 1.0 / np.where(chroma > 0.0, chroma, np.inf)  # a grey pixel has no hue: 0
    columns.append(mean_of(lab[:, 1] * unit))
    columns.append(mean_of(lab[:, 2] * unit))
    columns.append(mean_of(chroma / (np.maximum(lab[:, 0], 0.0) + 5.0)))
    every = owner[::2]
    for c in range(3):
        columns.extend(grouped.percentiles_many(every, lab[::2, c], n, PERCENTILES)[:, 1:])
    out: np.ndarray = np.nan_to_num(np.stack(columns, axis=1), nan=0.0)
    out[count == 0] = 0.0
    return out


__all__ = ["FEATURE_NAMES", "PERCENTILES", "instance_features", "srgb_to_lab"]
