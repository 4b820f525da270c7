"""The depth sensor's errors have the statistics their configuration says."""

from __future__ import annotations

import numpy as np
import pytest

from interfaces.camera import DepthNoise
from twin.camera.depth_noise import depth_edges, noisy_depth

SHAPE = (240, 320)


def plane(depth_m: float) -> np.ndarray:
    return np.full(SHAPE, depth_m, dtype=np.float32)


def test_the_axial_noise_grows_with_the_square_of_the_distance() -> None:
    noise = DepthNoise(
        base_std_m=0.0005, quadratic_std_per_m=0.0015, dropout=0.0, edge_dropout=0.0, quantum_m=0.0
    )
    rng = np.random.default_rng(4)
    for z in (0.6, 2.5):
        out = noisy_depth(plane(z), noise, rng, depth_min_m=0.3, depth_max_m=3.0)
        expected = noise.base_std_m + noise.quadratic_std_per_m * z**2
        assert out.dtype == np.float32
        assert np.isfinite(out).all()
        # 76800 samples: the sample std is within 1 % of the true one (its own std is 0.26 %)
        assert np.std(out) == pytest.approx(expected, rel=0.01)
        assert abs(float(np.mean(out)) - z) < 4 * expected / np.sqrt(out.size) + 1e-6


def test_dropouts_hit_discontinuities_at_their_rate_and_other_pixels_at_theirs() -> None:
    noise = DepthNoise(
        base_std_m=0.0,
        quadratic_std_per_m=0.0,
        edge_jump_m=0.01,
        edge_dropout=0.3,
        dropout=0.02,
        quantum_m=0.0,
    )
    depth = plane(1.2)
    depth[:, 160:] = 1.15  # a 5 cm step: columns 159 and 160 are its edge
    depth[100:140, 40:80] = 1.195  # a 5 mm step: below the jump, no edge
    edges = depth_edges(depth, noise.edge_jump_m)
    assert edges.sum() == 2 * SHAPE[0]
    assert edges[:, 159].all()
    assert edges[:, 160].all()
    dropped_edge, dropped_rest = [], []
    rng = np.random.default_rng(5)
    for _ in range(20):
        out = noisy_depth(depth, noise, rng, depth_min_m=0.3, depth_max_m=3.0)
        dropped_edge.append(np.isnan(out[edges]).mean())
        dropped_rest.append(np.isnan(out[~edges]).mean())
    # 9600 edge pixels: the rate's std is 0.0047; 1.5 M others: 0.00011
    assert np.mean(dropped_edge) == pytest.approx(0.3, abs=0.015)
    assert np.mean(dropped_rest) == pytest.approx(0.02, abs=0.001)
    # the values that were returned are the clean ones (no axial noise configured)
    returned = np.isfinite(out)
    np.testing.assert_array_equal(out[returned], depth[returned])


def test_nothing_is_returned_outside_the_range_and_values_are_quantised() -> None:
    noise = DepthNoise(
        base_std_m=0.0, quadratic_std_per_m=0.0, edge_dropout=0.0, dropout=0.0, quantum_m=0.001
    )
    depth = plane(1.2345)
    depth[:10] = 0.2  # nearer than the sensor's minimum
    depth[10:20] = 3.5  # beyond its maximum
    depth[20:30] = np.nan  # nothing there
    out = noisy_depth(depth, noise, np.random.default_rng(0), depth_min_m=0.3, depth_max_m=3.0)
    assert np.isnan(out[:30]).all()
    np.testing.assert_allclose(out[30:], 1.234, atol=1e-6)
    assert np.isnan(depth[20:30]).all()
    assert depth[0, 0] == np.float32(0.2)  # the input is left as it was


def test_a_pixel_next_to_no_return_is_an_edge() -> None:
    depth = plane(1.0)
    depth[50, 50] = np.nan
    edges = depth_edges(depth, 0.01)
    assert {(int(r), int(c)) for r, c in zip(*np.nonzero(edges), strict=True)} == {
        (50, 50),
        (49, 50),
        (51, 50),
        (50, 49),
        (50, 51),
    }


def test_the_same_seed_gives_the_same_noise() -> None:
    depth = plane(1.1)
    depth[:, 100:] = 0.9
    a = noisy_depth(depth, DepthNoise(), np.random.default_rng(9), depth_min_m=0.3, depth_max_m=3.0)
    b = noisy_depth(depth, DepthNoise(), np.random.default_rng(9), depth_min_m=0.3, depth_max_m=3.0)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(np.isnan(a), np.isnan(depth))  # something was dropped
