"""The gphoto2 driver end to end against libgphoto2's virtual PTP camera, which python-gphoto2's
wheels ship as the ``vusb`` I/O library: with ``VCAMERADIR`` set before gphoto2 is imported, the
wheel loads it instead of the USB one and the "camera" serves the files of that folder (a
capture duplicates one of its JPEGs). Each case runs in a child process, since libgphoto2
picks its I/O library once per process."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).parents[2]


def _vusb_dir() -> Path | None:
    spec = importlib.util.find_spec("gphoto2")
    if spec is None or spec.origin is None:
        return None
    folder = Path(spec.origin).parent / "libgphoto2" / "vusb"
    return folder if any(folder.glob("vusb.*")) else None


VUSB = _vusb_dir()
pytestmark = pytest.mark.skipif(
    VUSB is None, reason="this platform's python-gphoto2 has no virtual camera (libgphoto2/vusb)"
)


def jpeg_with_exif(path: Path, exposure_s: float | None = 1 / 60, iso: int | None = 200) -> bytes:
    """A small JPEG; with exposure/ISO/serial in its EXIF unless they are None."""
    from PIL import Image

    pixels = (np.random.default_rng(0).random((48, 64, 3)) * 255).astype(np.uint8)
    exif = Image.Exif()
    exif[0x0110] = "TestCam"  # Model
    sub = exif.get_ifd(0x8769)
    if exposure_s is not None:
        sub[0x829A] = exposure_s  # ExposureTime
    if iso is not None:
        sub[0x8827] = iso  # ISOSpeedRatings
        sub[0xA431] = "VC123"  # BodySerialNumber
    Image.fromarray(pixels).save(path, exif=exif)
    return path.read_bytes()


def in_vcamera(folder: Path, body: str, out: Path) -> dict:
    """Run ``body`` (with ``spec`` -> open_camera and ``out``) under the virtual camera;
    its result dict, or {"error": RigError text}."""
    script = textwrap.dedent(
        """
        import json, sys
        from pathlib import Path
        from core.errors import RigError
        from drivers.registry import open_camera
        out = Path(sys.argv[1])
        result = {}
        try:
        %s
        except RigError as error:
            result = {"error": str(error)}
        print(json.dumps(result))
        """
    ) % textwrap.indent(textwrap.dedent(body), "    ")
    env = {**os.environ, "VCAMERADIR": str(folder)}
    env.pop("IOLIBS", None)
    done = subprocess.run(
        [sys.executable, "-c", script, str(out)],
        env=env,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_capture_downloads_the_shot_with_its_exif(tmp_path: Path) -> None:
    folder = tmp_path / "card"
    folder.mkdir()
    original = jpeg_with_exif(folder / "IMG_0001.jpg")
    result = in_vcamera(
        folder,
        """
        camera = open_camera({"driver": "gphoto2", "settings": {"exposure_s": 0.01}})
        frames = [camera.capture(out, f"f{i:05d}") for i in range(2)]
        result = {
            "describe": camera.describe(),
            "shutter": camera.get_config("shutterspeed"),
            "frames": [
                {"paths": [str(p) for p in f.paths], "exposure_s": f.exposure_s, "iso": f.iso,
                 "serial": f.camera_serial, "extra": f.extra}
                for f in frames
            ],
        }
        camera.close()
        """,
        tmp_path / "incoming",
    )
    assert result["describe"]["driver"] == "gphoto2" and result["describe"]["model"] == "VC"
    assert result["shutter"] == "0.0100s"  # camera_settings.exposure_s picked the closest choice
    for index, frame in enumerate(result["frames"]):
        (path,) = frame["paths"]
        assert Path(path).name == f"f{index:05d}.jpg"
        assert Path(path).read_bytes() == original  # the download is the camera's file, whole
        assert frame["exposure_s"] == pytest.approx(1 / 60) and frame["iso"] == 200.0
        assert frame["serial"] == "VC123"
        assert frame["extra"]["camera_files"][0].startswith("/store_")


def test_missing_exposure_falls_back_to_the_camera_then_fails_clearly(tmp_path: Path) -> None:
    folder = tmp_path / "card"
    folder.mkdir()
    jpeg_with_exif(folder / "IMG_0001.jpg", exposure_s=None, iso=None)
    result = in_vcamera(
        folder,
        """
        camera = open_camera({"driver": "gphoto2"})
        camera.capture(out, "f00000")
        """,
        tmp_path / "incoming",
    )
    assert "camera did not report exposure/ISO for f00000.jpg" in result["error"]
    assert "manual exposure" in result["error"]


@pytest.mark.parametrize(
    ("spec", "message"),
    [
        ({"capture_target": "floppy"}, "capture_target 'floppy' is not known"),
        ({"port": "nosuch:1"}, "no camera port 'nosuch:1'"),
        ({"settings": {"iso": 400}}, "the camera has none of the settings iso, isospeed"),
        ({"settings": {"exposure_s": 7.0}}, "offers no shutterspeed matching"),
        ({"config": {"capturetarget": "Floppy"}}, "the camera refuses capturetarget = 'Floppy'"),
        ({"config": {"nosuchwidget": "1"}}, "the camera has no setting 'nosuchwidget'"),
        ({"unknown_key": 1}, "key 'unknown_key' is not known"),
    ],
)
def test_bad_settings_are_named(tmp_path: Path, spec: dict, message: str) -> None:
    folder = tmp_path / "card"
    folder.mkdir()
    jpeg_with_exif(folder / "IMG_0001.jpg")
    full = json.dumps({"driver": "gphoto2", **spec})
    result = in_vcamera(folder, f"open_camera({full})", tmp_path / "incoming")
    assert message in result["error"]


def test_a_camera_with_nothing_to_capture_is_a_clear_error(tmp_path: Path) -> None:
    folder = tmp_path / "card"
    folder.mkdir()
    (folder / "notes.txt").write_text("no JPEG to duplicate")
    result = in_vcamera(
        folder,
        """
        camera = open_camera({"driver": "gphoto2"})
        camera.capture(out, "f00000")
        """,
        tmp_path / "incoming",
    )
    assert result["error"].startswith("camera failed to capture:")
    assert not any((tmp_path / "incoming").glob("f00000*"))  # nothing half-written left
