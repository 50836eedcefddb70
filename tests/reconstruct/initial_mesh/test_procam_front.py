"""run_front on a projector session (simulated camera + projector, two placements): the
initial mesh comes from the Gray code, the optimiser gets the projector's light position per
view and only the uniform-colour frames as observations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from core.errors import RigError
from core.labels import is_structured
from reconstruct.initial_mesh.dense.poisson import read_mesh
from reconstruct.initial_mesh.procam import ProcamConfig
from reconstruct.model.camera import write_colmap_text
from reconstruct.run.front import FrontConfig, run_front
from tests.reconstruct.initial_mesh import sim_session


@pytest.mark.slow
def test_projector_session_takes_the_procam_path(tmp_path: Path) -> None:
    root = tmp_path / "session"
    rig, cams = sim_session.capture(root, plate=False, colours=("red", "green"))
    write_colmap_text(
        root / "poses", {1: sim_session.intrinsics()},
        {v + 1: (1, f"view_{v:04d}", p) for v, p in enumerate(cams)},
    )
    result = run_front(root, {"mesh": {"voxels": 64}})
    assert result.initial_mesh_path == root / "recon" / "procam" / "initial.ply"
    assert not (root / "recon" / "mesh").exists()  # no visual hull
    assert result.structured_light and result.light_mode_hint == "free"
    assert set(result.frames) == {(v, c) for v in range(6) for c in ("red", "green")}
    assert not any(is_structured(label) for _, label in result.frames)
    _, placement, projectors = sim_session.layout(plate=False)
    lights = result.initial_light_positions
    assert lights is not None and lights.shape == (6, 3)
    truth = np.array([projectors[placement[v]].center for v in sorted(result.poses)])
    error = np.linalg.norm(lights - truth, axis=1)
    truth_mesh = trimesh.Trimesh(rig.scene.vertices, rig.scene.faces, process=False)
    points = read_mesh(result.initial_mesh_path).sample(2000, seed=0)
    distance = np.abs(trimesh.proximity.signed_distance(truth_mesh, points))
    print(f"projector session via run_front: light positions within {error.max() * 1e3:.1f} mm,"
          f" initial mesh mean distance {distance.mean() * 1e3:.2f} mm to the true surface")
    assert error.max() < 0.02
    assert distance.mean() < 1e-3
    assert (result.visibility.counts() > 0).mean() > 0.3


def test_procam_options_are_a_config_section() -> None:
    conf = FrontConfig.from_mapping({"procam": {"mode": "plate", "projector_focal_px": 220.0}})
    assert conf.procam == ProcamConfig(mode="plate", projector_focal_px=220.0)
    with pytest.raises(RigError, match="procam"):
        FrontConfig.from_mapping({"procam": {"focal": 1.0}})
