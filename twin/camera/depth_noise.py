"""A depth sensor's errors on a rendered depth image (:class:`interfaces.camera.DepthNoise`).

In this order, all vectorised over the image:

1. discontinuities are found on the clean image: a pixel whose right or lower neighbour
   differs by more than ``edge_jump_m``, or returned nothing where it did (and that neighbour
   too);
2. axial noise: ``z + N(0, 1) * (base_std_m + quadratic_std_per_m * z**2)``, the error of a
   stereo or structured-light sensor, growing with the square of the distance;
3. quantisation to ``quantum_m``;
4. dropouts: a pixel on a discontinuity returns nothing with probability ``edge_dropout``,
   any other with probability ``dropout``;
5. nothing (NaN) outside the sensor's range ``[depth_min_m, depth_max_m]``.

The random numbers come from the caller's :class:`numpy.random.Generator` (the twin's seed
tree decides it), one normal and one uniform draw per pixel whatever the image holds, so a seed
gives the same noise for the same image.
"""

from __future__ import annotations

import numpy as np

from interfaces.camera import DepthNoise

__all__ = ["depth_edges", "noisy_depth"]


def depth_edges(depth_m: np.ndarray, jump_m: float) -> np.ndarray:
    """The pixels ``(H, W) bool`` on a depth discontinuity: both pixels of every pair of
    horizontal or vertical neighbours whose depths differ by more than ``jump_m``, or of which
    exactly one is NaN."""
    z = np.asarray(depth_m, dtype=np.float32)
    finite = np.isfinite(z)
    edges = np.zeros(z.shape, dtype=bool)
    for first, second in (
        ((slice(None, -1), slice(None)), (slice(1, None), slice(None))),  # vertical pairs
        ((slice(None), slice(None, -1)), (slice(None), slice(1, None))),  # horizontal pairs
    ):
        step = np.subtract(z[first], z[second])
        np.abs(step, out=step)
        with np.errstate(invalid="ignore"):
            jump = step > jump_m
        jump |= finite[first] != finite[second]
        edges[first] |= jump
        edges[second] |= jump
    return edges


def noisy_depth(
    depth_m: np.ndarray,
    noise: DepthNoise,
    rng: np.random.Generator,
    *,
    depth_min_m: float,
    depth_max_m: float,
) -> np.ndarray:
    """``depth_m`` ``(H, W)`` (m, NaN: nothing) as the sensor of ``noise`` returns it,
    ``(H, W) float32`` (a new array; the input is left as it is).

    Computed in place as far as it goes: a fresh temporary of a frame's size costs more in
    page faults than the arithmetic.
    """
    clean = np.asarray(depth_m, dtype=np.float32)
    shape = clean.shape
    gaussian = rng.standard_normal(shape, dtype=np.float32)
    uniform = rng.random(shape, dtype=np.float32)
    if noise.base_std_m > 0.0 or noise.quadratic_std_per_m > 0.0:
        z = np.multiply(clean, clean)
        z *= np.float32(noise.quadratic_std_per_m)
        z += np.float32(noise.base_std_m)  # the std at each pixel
        z *= gaussian
        z += clean
    else:
        z = clean.copy()
    if noise.quantum_m > 0.0:
        quantum = np.float32(noise.quantum_m)
        z /= quantum
        np.round(z, out=z)
        z *= quantum
    if noise.edge_dropout > 0.0 or noise.dropout > 0.0:
        dropped = uniform < np.float32(noise.dropout)
        if noise.edge_dropout > 0.0:
            at_edge = uniform < np.float32(noise.edge_dropout)
            np.copyto(dropped, at_edge, where=depth_edges(clean, noise.edge_jump_m))
        np.copyto(z, np.float32(np.nan), where=dropped)
    with np.errstate(invalid="ignore"):
        outside = z < np.float32(depth_min_m)
        outside |= z > np.float32(depth_max_m)
    np.copyto(z, np.float32(np.nan), where=outside)
    return z
