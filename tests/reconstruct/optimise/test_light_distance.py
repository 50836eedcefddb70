"""The capture's spread of camera distances, which decides whether the light's distance on the
camera plate is observable apart from the reflectance scale, and the warning when it is not."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
import pytest

from reconstruct.model.camera import Pose
from reconstruct.optimise.synthetic import SyntheticScene
from reconstruct.run.pipeline import (
    MIN_DISTANCE_RATIO,
    camera_distances,
    warn_if_light_distance_weak,
)


def test_one_ring_is_flagged_and_stepping_in_and_out_is_not(
    scene: SyntheticScene, caplog: pytest.LogCaptureFixture
) -> None:
    inp = scene.input()
    centre = inp.vertices.mean(axis=0)
    ring = camera_distances(inp)
    assert ring["ratio"] == pytest.approx(ring["max"] / ring["min"])
    assert ring["min"] <= ring["median"] <= ring["max"]
    # Scale every other camera's distance to the centroid by 1.6: a hand-held step back.
    poses = [
        Pose.look_at(centre + (1.6 if k % 2 else 1.0) * (p.center - centre), centre)
        for k, p in enumerate(inp.rig.poses)
    ]
    stepped = camera_distances(replace(inp, rig=replace(inp.rig, poses=poses)))
    assert stepped["ratio"] == pytest.approx(1.6 * ring["ratio"], rel=0.2)
    assert stepped["ratio"] >= MIN_DISTANCE_RATIO > ring["ratio"]

    with caplog.at_level(logging.WARNING, logger="reconstruct"):
        warn_if_light_distance_weak(ring, "offset")
    assert "closer and some farther" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="reconstruct"):
        warn_if_light_distance_weak(stepped, "offset")
        warn_if_light_distance_weak(ring, "fixed")  # known lights: nothing to observe
    assert caplog.text == ""
    np.testing.assert_allclose(
        [np.linalg.norm(p.center - centre) for p in poses[1::2]],
        [1.6 * np.linalg.norm(p.center - centre) for p in inp.rig.poses[1::2]],
    )
