"""formation.detect_neighbours: the agent's neighbour detector (formation_perception::neighbours)
from Python, against discs cast exactly here and against the world's own scans and poses."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import REPO

import formation


def cast(centres, beams=900, max_range=10.0, radius=0.25) -> np.ndarray:
    """The body-frame scan of discs of `radius` at `centres`: each beam `k`, at bearing
    `2 pi k / beams`, meets the nearest disc where `t^2 - 2 (u.c) t + |c|^2 - r^2 = 0`."""
    bearing = 2.0 * np.pi * np.arange(beams) / beams
    u = np.stack([np.cos(bearing), np.sin(bearing)], axis=1)
    scan = np.full(beams, max_range)
    for cx, cy in centres:
        along = u @ np.array([cx, cy])
        disc = along**2 - (cx * cx + cy * cy - radius * radius)
        t = along - np.sqrt(np.maximum(disc, 0.0))
        scan = np.where((disc >= 0.0) & (t > 0.0), np.minimum(scan, t), scan)
    return np.minimum(scan, max_range).astype(np.float32)


def errors(found: np.ndarray, centres) -> np.ndarray:
    """For each true centre, the distance to the nearest detection."""
    return np.array([np.min(np.hypot(*(found - np.array(c)).T)) for c in centres])


def test_discs_cast_exactly_are_found_to_a_millimetre_nearest_first():
    centres = [(1.5, 0.0), (-0.8, 1.1), (0.3, -2.6), (3.0, 3.0)]
    found = formation.detect_neighbours(cast(centres))
    assert found.shape == (4, 2) and found.dtype == np.float64
    distances = np.hypot(found[:, 0], found[:, 1])
    assert np.all(np.diff(distances) >= 0.0)
    assert np.all(errors(found, centres) < 1e-3), found
    # The nearest is (-0.8, 1.1): ahead is +x, left is +y.
    assert np.allclose(found[0], [-0.8, 1.1], atol=1e-3)


def test_any_float_array_another_radius_and_another_lidar():
    # A TurtleBot3 Burger's 0.105 m body and 360-beam 3.5 m LIDAR, the scan as float64.
    centres = [(0.6, -0.4), (-1.0, 0.2)]
    scan = cast(centres, beams=360, max_range=3.5, radius=0.105).astype(np.float64)
    found = formation.detect_neighbours(scan, max_range=3.5, body_radius=0.105)
    assert found.shape == (2, 2)
    assert np.all(errors(found, centres) < 1e-3), found
    # The same scan read with the default 0.25 m body fits circles too large: centres move.
    wrong = formation.detect_neighbours(scan, max_range=3.5)
    assert wrong.shape[0] == 0 or np.max(errors(wrong, centres)) > 0.05


def test_nothing_to_see_gives_an_empty_array():
    assert formation.detect_neighbours(np.full(900, 10.0, np.float32)).shape == (0, 2)
    assert formation.detect_neighbours(np.full(900, np.nan)).shape == (0, 2)
    assert formation.detect_neighbours(np.zeros(0, np.float32)).shape == (0, 2)
    garbage = np.tile([np.inf, -1.0, np.nan, 1e30], 225)
    assert formation.detect_neighbours(garbage).shape == (0, 2)


def test_bad_settings_raise_naming_them():
    scan = cast([(1.0, 0.0)])
    with pytest.raises(ValueError, match="body_radius"):
        formation.detect_neighbours(scan, body_radius=-0.25)
    with pytest.raises(ValueError, match="max_range"):
        formation.detect_neighbours(scan, max_range=float("nan"))


def test_the_world_s_own_scans_give_its_robots_in_each_body_frame():
    scenario = formation.Scenario(
        REPO / "scenarios" / "teams-generalist.toml",
        robots=8,
        overrides={"lidar.noise_std": 0.0},
    )
    batch = formation.Batch(scenario, seeds=[7], runs=[2])
    poses, scans = batch.poses()[0], batch.scans()[0]
    for i, (x, y, theta) in enumerate(poses):
        offsets = np.delete(poses[:, :2], i, axis=0) - [x, y]
        c, s = np.cos(theta), np.sin(theta)
        body = np.stack([c * offsets[:, 0] + s * offsets[:, 1], -s * offsets[:, 0] + c * offsets[:, 1]], 1)
        found = formation.detect_neighbours(scans[i])
        assert len(found) >= 1
        # Every detection is a robot, to a millimetre, and the nearest robot is found.
        for f in found:
            assert np.min(np.hypot(*(body - f).T)) < 1e-3, (i, f)
        nearest = body[np.argmin(np.hypot(body[:, 0], body[:, 1]))]
        assert np.allclose(found[0], nearest, atol=1e-3), (i, found[0], nearest)
