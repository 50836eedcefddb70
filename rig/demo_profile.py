"""The shipped sim profile sized for `rig demo` (and the kernel warm-up's tiny capture)."""

from __future__ import annotations

import copy
from importlib import resources
from typing import Any

import yaml

DEMO_START_AZIMUTH_DEG = 10.0


def demo_profile(views: int) -> dict[str, Any]:
    """The shipped sim profile, sized for a demo: two illuminations, poses estimated from the
    images (the scene stands on the profile's marker board), an exposure that fills the
    sensor."""
    text = (resources.files("profiles") / "sim.yaml").read_text(encoding="utf-8")
    profile = copy.deepcopy(yaml.safe_load(text))
    profile["name"] = "sim-demo"
    profile["description"] = "rig demo: simulated rig, two illuminations, poses from the images"
    profile["camera_settings"] = {"exposure_s": 1.0, "iso": 250}
    profile["illuminations"] = {k: profile["illuminations"][k] for k in ("LED1", "LED2")}
    profile["plan"]["views"] = int(views)
    profile["poses"] = "estimate"
    # From azimuth 0 the first (closest) view sees the board end-on with the object over its
    # middle: too few board corners for a board pose, and a warning in every demo's log.
    profile["sim"]["trajectory"]["start_azimuth_deg"] = DEMO_START_AZIMUTH_DEG
    return profile
