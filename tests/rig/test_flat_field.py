"""The flat-field step end to end on the simulated rig: the wizard photographs the sim's white
card through a lens with fall-off, stores the flat field, a capture records it and decode
divides by it, so the white card decodes flat; the standalone command fits the same frames."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from calibration.flat_field import card_shading
from calibration.store import CalibrationStore
from core.session import Session
from drivers.sim.camera import VignettingConfig
from drivers.sim.rig import SimRig
from drivers.sim.white_card import card_distance
from reconstruct.frames.decode import DecodeIndex, load_frame
from reconstruct.frames.decode import run as decode
from rig.capture import run_capture
from rig.cli import main

PROFILE = Path(__file__).with_name("sim-small.yaml")
CAMERA = {"width": 160, "height": 120, "focal_px": 200.0, "supersample": 1}
FALL_OFF = {"cos4": True, "extra": 0.3}
LENS = VignettingConfig(cos4=True, extra=0.3)  # = FALL_OFF
FLAT_TOLERANCE = 0.03  # corner / centre of the corrected card, texture and noise included


def profile(tmp_path: Path, store: Path | str, **sim: Any) -> Path:
    data = yaml.safe_load(PROFILE.read_text())
    data["calibration"] = {
        "store": str(store),
        "camera": "Canon EOS 5D Mark II",
        "flat_field": "flat/sim",
    }
    data["camera_settings"] = {"exposure_s": 0.8, "iso": 400}
    data["plan"] = {"views": 1, "illuminations": ["LED1"], "ambient": False}
    data["sim"] = {"subdivisions": 2, "camera": {**CAMERA, "vignetting": FALL_OFF}, **sim}
    path = tmp_path / "rig.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def card_session(tmp_path: Path, rig_yaml: Path) -> tuple[Path, float]:
    """One view of the sim's white card, head-on, the light on the plate."""
    distance = card_distance(SimRig({"scene": "chart", "camera": CAMERA, "subdivisions": 0}))
    data = yaml.safe_load(rig_yaml.read_text())
    data["sim"].update(
        scene="card", trajectory={"elevations_deg": [90.0], "radius_m": distance}
    )
    path = tmp_path / "card.yaml"
    path.write_text(yaml.safe_dump(data))
    out = run_capture(str(path), tmp_path / "card-session", yes=True)
    return Path(out), distance


def corner_to_centre(image: np.ndarray) -> float:
    """Mean of the four 10x10 corners over the 10x10 centre (green channel)."""
    g = image[..., 1]
    h, w = g.shape
    corners = [g[:10, :10], g[:10, -10:], g[-10:, :10], g[-10:, -10:]]
    centre = g[h // 2 - 5 : h // 2 + 5, w // 2 - 5 : w // 2 + 5]
    return float(np.mean([c.mean() for c in corners]) / centre.mean())


def decoded_card(session: Path, distance: float) -> np.ndarray:
    """The decoded card frame divided by the light's own fall-off on the card."""
    out = decode({}, session, session / "recon" / "decoded")
    frame = DecodeIndex.load(out).frames[0]
    image, _ = load_frame(out, frame)
    shading = card_shading(160, 120, 200.0, distance, (0.1, 0.0, 0.0))
    return image / shading[..., None]


def test_wizard_flat_field_step_makes_the_decoded_white_card_flat(tmp_path: Path) -> None:
    store_dir = tmp_path / "store"
    rig_yaml = profile(tmp_path, store_dir)
    assert main(["calibrate", "wizard", "--yes", "--profile", str(rig_yaml),
                 "--store", str(store_dir)]) == 0
    entry, flat = CalibrationStore(store_dir).flat_field("flat/sim")
    assert flat.method == "white card" and flat.details["frames"] == 4
    truth = LENS.gain(SimRig({"camera": CAMERA, "scene": "chart", "subdivisions": 0}).intrinsics)
    assert np.abs(flat.gain(160, 120) - truth[..., None]).max() < 0.02
    # a capture with that store records the flat field, and decode divides by it
    session, distance = card_session(tmp_path, rig_yaml)
    info = Session.open(session).info
    assert info.calibration.flat_field is not None
    assert (info.calibration.flat_field.entry, info.calibration.flat_field.version) == (
        "flat/sim", entry.version)
    corrected = corner_to_centre(decoded_card(session, distance))
    assert abs(corrected - 1.0) < FLAT_TOLERANCE
    # the same session without the flat field falls off towards the corners
    info_file = session / "session.yaml"
    data = yaml.safe_load(info_file.read_text())
    data["calibration"]["flat_field"] = None
    info_file.write_text(yaml.safe_dump(data))
    uncorrected = corner_to_centre(decoded_card(session, distance))
    assert uncorrected < 0.6  # cos⁴ and the lens's own 30 % at the corners
    assert abs(uncorrected / corrected - truth[:10, :10].mean() / truth[55:65, 75:85].mean()) \
        < 0.02


def test_flat_field_command_fits_white_card_raws(tmp_path: Path) -> None:
    rig = SimRig({"scene": "chart", "subdivisions": 0, "light_offset_m": [0.1, 0.0, 0.0],
                  "camera": {**CAMERA, "vignetting": FALL_OFF, "exposure_s": 0.8, "iso": 400}})
    from drivers.sim.white_card import white_card

    raws, darks = [], []
    for position in range(3):
        card = white_card(rig, position)
        card.light.set_levels({"c": 1.0})
        raws.append(str(card.camera.capture(tmp_path, f"card{position}").paths[0]))
        card.light.off()
        darks += ["--dark", str(card.camera.capture(tmp_path, f"dark{position}").paths[0])]
        card.close()
    store_dir = tmp_path / "store"
    args = ["calibrate", "flat-field", *raws, *darks, "--camera", "SimCam", "--store",
            str(store_dir), "--card-distance-m", str(card.distance_m), "--focal-px", "200",
            "--light-offset-m", "0.1,0,0"]
    assert main(args) == 0
    _, flat = CalibrationStore(store_dir).flat_field("flat/SimCam")
    truth = LENS.gain(rig.intrinsics)
    assert np.abs(flat.gain(160, 120) - truth[..., None]).max() < 0.02
    # without the card's geometry the light's own fall-off would be taken for the lens's
    assert main(args[:-6] + ["--name", "flat/raw", "--diffuser"]) == 0
    _, wrong = CalibrationStore(store_dir).flat_field("flat/raw")
    assert wrong.corner_gain()[1] < flat.corner_gain()[1] - 0.1


def test_flat_field_errors_are_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    store = ["--store", str(tmp_path / "s")]
    assert main(["calibrate", "flat-field", *store]) == 2
    assert "--camera" in capsys.readouterr().err
    assert main(["calibrate", "flat-field", "x.dng", "--camera", "c", *store]) == 2
    assert "--card-distance-m" in capsys.readouterr().err
    # a real rig (no device sets up the card) with --yes needs the card's geometry
    from rig.capture.devices import RigDevices

    monkeypatch.setattr(RigDevices, "white_card_source", property(lambda self: None))
    rig_yaml = profile(tmp_path, tmp_path / "store")
    wizard = ["calibrate", "wizard", "--yes", "--profile", str(rig_yaml), *store]
    assert main(wizard) == 2
    assert "--card-distance-m and --focal-px" in capsys.readouterr().err
        # a profile naming a flat field of the built-in store is refused before capturing
    rig_yaml = profile(tmp_path, "default")
    with pytest.raises(Exception, match="flat_field"):
        run_capture(str(rig_yaml), tmp_path / "session", yes=True)


RECON_CONFIG = """\
subdivide: {max_steps: 1, max_faces: 4000}
optimise: {outer_iterations: 3, light_iterations: 10, joint_iterations: 8}
"""


def reconstruct_and_evaluate(session: Path, config: Path) -> dict[str, float]:
    from reconstruct.outputs.evaluate import evaluate

    truth = session / "ground_truth"
    assert main(["reconstruct", str(session), "--config", str(config),
                 "--initial-mesh", str(truth / "mesh.ply")]) == 0
    rig_truth = yaml.safe_load((truth / "rig.yaml").read_text())
    ev = evaluate(session / "recon", truth / "mesh.ply", truth / "reflectance.npy",
                  np.asarray(rig_truth["light_offset_m"]))
    d65 = next(c for c in ev.colour if c["illuminant"] == "D65")
    return {"accuracy_mm": 1e3 * ev.accuracy_m, "spectral_rmse": ev.spectral_rmse,
            "de00_vertex": d65["per_vertex"]["mean"], "de00_patch": d65["patch_mean"],
            "light_offset_mm": 1e3 * float(ev.light_offset_error_m or 0.0)}


@pytest.mark.slow
def test_reconstruction_with_fall_off_with_and_without_the_flat_field(tmp_path: Path) -> None:
    """The same frames through a lens with fall-off, reconstructed with and without the
    wizard's flat field, and an ideal lens for reference (printed; a loose check)."""
    import shutil

    store_dir = tmp_path / "store"
    data = yaml.safe_load(profile(tmp_path, store_dir).read_text())
    data["plan"] = {
        "views": 12,
        "illuminations": ["LED2", "LED3"],
        "ambient": False,
        "trajectory": {"distance_factors": [0.8, 1.0, 1.3]},  # the light distance observable
    }
    data["poses"] = "known"
    data["sim"]["subdivisions"] = 3
    data["sim"]["camera"].update(width=128, height=96, focal_px=160.0)
    rig_yaml = tmp_path / "tiny.yaml"
    rig_yaml.write_text(yaml.safe_dump(data))
    assert main(["calibrate", "wizard", "--yes", "--profile", str(rig_yaml),
                 "--store", str(store_dir)]) == 0
    config = tmp_path / "recon.yaml"
    config.write_text(RECON_CONFIG)
    corrected = Path(run_capture(str(rig_yaml), tmp_path / "corrected", yes=True))
    plain = tmp_path / "plain"
    shutil.copytree(corrected, plain)  # the same frames, decoded without the flat field
    info = yaml.safe_load((plain / "session.yaml").read_text())
    info["calibration"]["flat_field"] = None
    (plain / "session.yaml").write_text(yaml.safe_dump(info))
    del data["calibration"]["flat_field"]
    del data["sim"]["camera"]["vignetting"]
    ideal_yaml = tmp_path / "ideal.yaml"
    ideal_yaml.write_text(yaml.safe_dump(data))
    ideal = Path(run_capture(str(ideal_yaml), tmp_path / "ideal", yes=True))
    rows = {name: reconstruct_and_evaluate(s, config)
            for name, s in (("ideal lens", ideal), ("fall-off, flat field", corrected),
                            ("fall-off, uncorrected", plain))}
    for name, row in rows.items():
        print(name, {k: round(v, 4) for k, v in row.items()})
    report = yaml.safe_load((corrected / "recon" / "report.json").read_text())
    assert report["flat_field"]["entry"] == "flat/sim"
    assert "none" in yaml.safe_load((plain / "recon" / "report.json").read_text())["flat_field"]
    # with the flat field the fall-off costs (nearly) nothing against an ideal lens
    for key in ("spectral_rmse", "de00_vertex", "accuracy_mm"):
        assert rows["fall-off, flat field"][key] < 1.05 * rows["ideal lens"][key]


def test_wizard_asks_a_person_for_the_card_and_its_distance(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without a device that sets the card up, the person holds it (here the sim camera looks
    at the card scene) and answers the distance and focal length prompts."""
    from rich.console import Console

    from rig.capture.devices import RigDevices

    distance = card_distance(SimRig({"scene": "chart", "camera": CAMERA, "subdivisions": 0}))
    asked: list[str] = []

    def answer(self: Console, prompt: str = "", **_: object) -> str:
        asked.append(prompt)
        if "distance in m" in prompt and prompt.startswith("flat field"):
            return str(distance)
        return "200" if "focal length in pixels" in prompt else ""

    monkeypatch.setattr(Console, "input", answer)
    monkeypatch.setattr(RigDevices, "white_card_source", property(lambda self: None))
    store_dir = tmp_path / "store"
    rig_yaml = profile(
        tmp_path, store_dir, scene="card",
        trajectory={"elevations_deg": [90.0], "radius_m": distance},
    )
    args = ["calibrate", "wizard", "--profile", str(rig_yaml), "--store", str(store_dir),
            "--flat-field-positions", "2"]
    assert main(args) == 0
    flat_prompts = [p for p in asked if p.startswith("flat field")]
    assert [p.split(":")[0] for p in flat_prompts] == [
        "flat field", "flat field", "flat field 1/2", "flat field 2/2"]
    _, flat = CalibrationStore(store_dir).flat_field("flat/sim")
    truth = LENS.gain(SimRig({"camera": CAMERA, "scene": "chart", "subdivisions": 0}).intrinsics)
    assert np.abs(flat.gain(160, 120) - truth[..., None]).max() < 0.03
