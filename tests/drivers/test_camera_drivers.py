"""Cameras: gphoto2 against a fake gphoto2 module, folder-watch with a simulated tethering
app, hand-held import ordered by EXIF time, and the small EXIF reader on real files."""

from __future__ import annotations

import logging
import os
import threading
from datetime import datetime, timezone
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from PIL import Image

from core.errors import RigError
from core.files import temporary_name
from drivers.cameras.exif import ExifInfo, read_exif
from drivers.cameras.files import copy_durably, write_durably
from drivers.cameras.folder_watch import FolderWatchCamera, frame_from_files
from drivers.cameras.gphoto2_camera import Gphoto2Camera, parse_shutter
from drivers.cameras.handheld import HandheldImportCamera, match_files_to_frames
from drivers.protocols import Camera
from drivers.sim.dng import write_dng

# -- fake python-gphoto2 --------------------------------------------------------------------
GP_WIDGET_TEXT, GP_WIDGET_RADIO, GP_WIDGET_MENU = 2, 5, 6  # libgphoto2's CameraWidgetType


class FakeGPhoto2Error(Exception):
    def __init__(self, code: int, text: str = "error") -> None:
        super().__init__(f"[{code}] {text}")
        self.code = code


class FakeWidget:
    def __init__(self, values: dict[str, str], choices: dict[str, list[str]]) -> None:
        self.values, self.choices = values, choices

    def get_child_by_name(self, name: str) -> SimpleNamespace:
        if name not in self.values:
            raise FakeGPhoto2Error(-2, "Bad parameters")

        def set_value(value: str) -> None:
            if name in self.choices and value not in self.choices[name]:
                raise FakeGPhoto2Error(-2, "Bad parameters")
            self.values[name] = value

        return SimpleNamespace(
            get_value=lambda: self.values[name],
            set_value=set_value,
            get_choices=lambda: iter(self.choices.get(name, [])),
            get_type=lambda: GP_WIDGET_RADIO if name in self.choices else GP_WIDGET_TEXT,
        )


class FakeCamera:
    """Shoots RAW+JPEG into RAM; can be made busy for N calls or hang forever."""

    def __init__(self) -> None:
        self.values = {
            "serialnumber": "083012345",
            "shutterspeed": "1/125",
            "iso": "200",
            "aperture": "f/5.6",
            "imageformat": "Large Fine JPEG",
            "capturetarget": "Memory card",
        }
        self.widget = FakeWidget(
            self.values,
            {
                "iso": ["100", "200", "400"],
                "shutterspeed": ["1/15", "1/30", "1/60", "1/125"],
                "aperture": ["f/5.6", "f/8", "f/11"],
                "imageformat": ["Large Fine JPEG", "RAW + Large Fine JPEG", "RAW"],
            },
        )
        self.busy_for = 0
        self.hang = threading.Event()
        self.hanging = False
        self.deleted: list[str] = []
        self.events = [(2, SimpleNamespace(folder="/store", name="IMG_0001.JPG")), (4, None)]

    def init(self) -> None: ...

    def exit(self) -> None: ...

    def get_summary(self) -> str:
        return "Manufacturer: Canon Inc.\nModel: Canon EOS 550D\n"

    def get_config(self) -> FakeWidget:
        return self.widget

    def set_config(self, config: FakeWidget) -> None: ...

    def capture(self, kind: int) -> SimpleNamespace:
        if self.hanging:
            self.hang.wait(10)
        if self.busy_for:
            self.busy_for -= 1
            raise FakeGPhoto2Error(-110, "I/O in progress (PTP device busy)")
        return SimpleNamespace(folder="/store", name="IMG_0001.CR2")

    def wait_for_event(self, timeout_ms: int) -> tuple[int, object]:
        return self.events.pop(0) if self.events else (1, None)

    def file_get(self, folder: str, name: str, kind: int) -> SimpleNamespace:
        return SimpleNamespace(get_data_and_size=lambda: f"{folder}/{name}".encode())

    def file_delete(self, folder: str, name: str) -> None:
        self.deleted.append(name)


def fake_gphoto2(camera: FakeCamera) -> SimpleNamespace:
    return SimpleNamespace(
        Camera=lambda: camera,
        GPhoto2Error=FakeGPhoto2Error,
        GP_ERROR_CAMERA_BUSY=-110,
        GP_ERROR_BAD_PARAMETERS=-2,
        GP_WIDGET_RADIO=GP_WIDGET_RADIO,
        GP_WIDGET_MENU=GP_WIDGET_MENU,
        GP_CAPTURE_IMAGE=0,
        GP_FILE_TYPE_NORMAL=1,
        GP_EVENT_TIMEOUT=1,
        GP_EVENT_FILE_ADDED=2,
        GP_EVENT_CAPTURE_COMPLETE=4,
    )


def test_gphoto2_capture_downloads_raw_and_jpeg_with_metadata(tmp_path: Path) -> None:
    fake = FakeCamera()
    cam = Gphoto2Camera(gp=fake_gphoto2(fake), config={"iso": "200"})
    assert isinstance(cam, Camera)
    assert fake.values["capturetarget"] == "Internal RAM"
    frame = cam.capture(tmp_path / "raw", "f0000")
    assert [p.name for p in frame.paths] == ["f0000.cr2", "f0000.jpg"]
    assert frame.paths[0].read_bytes() == b"/store/IMG_0001.CR2"
    assert (frame.exposure_s, frame.iso, frame.camera_serial) == (1 / 125, 200.0, "083012345")
    assert fake.deleted == ["IMG_0001.CR2", "IMG_0001.JPG"]
    assert [p.name for p in (tmp_path / "raw").iterdir()] == ["f0000.cr2", "f0000.jpg"]
    assert cam.describe()["model"] == "Canon EOS 550D"


def test_gphoto2_busy_camera_is_retried_with_backoff(tmp_path: Path) -> None:
    fake = FakeCamera()
    slept: list[float] = []
    cam = Gphoto2Camera(gp=fake_gphoto2(fake), sleep=slept.append, busy_retries=3)
    fake.busy_for = 2
    cam.capture(tmp_path, "f1")
    assert slept == [0.25, 0.5]
    fake.busy_for = 10
    with pytest.raises(RigError, match="PTP device busy"):
        cam.capture(tmp_path, "f2")
    assert len(slept) == 2 + 3


def test_gphoto2_hung_camera_times_out_instead_of_hanging(tmp_path: Path) -> None:
    fake = FakeCamera()
    cam = Gphoto2Camera(gp=fake_gphoto2(fake), timeout_s=0.2)
    fake.hanging = True
    try:
        with pytest.raises(RigError, match="did not finish within 0.2 s"):
            cam.capture(tmp_path, "f0")
        with pytest.raises(RigError, match="stopped answering"):
            cam.capture(tmp_path, "f1")
    finally:
        fake.hang.set()


def test_gphoto2_refused_setting_lists_the_choices() -> None:
    with pytest.raises(RigError, match="allowed values: 100, 200, 400"):
        Gphoto2Camera(gp=fake_gphoto2(FakeCamera()), config={"iso": "12800"})
    with pytest.raises(RigError, match="no setting 'whitebalance'"):
        Gphoto2Camera(gp=fake_gphoto2(FakeCamera()), config={"whitebalance": "Daylight"})


def test_profile_camera_settings_pick_the_cameras_own_choices(monkeypatch) -> None:
    import sys

    from drivers.registry import open_camera

    fake = FakeCamera()
    monkeypatch.setitem(sys.modules, "gphoto2", fake_gphoto2(fake))
    settings = {"exposure_s": 0.0333, "iso": 100, "aperture": 8, "format": "RAW"}
    cam = open_camera({"driver": "gphoto2", "transport": {"kind": "usb"}, "settings": settings})
    assert cam.describe()["serial"] == "083012345"
    assert (fake.values["shutterspeed"], fake.values["iso"]) == ("1/30", "100")
    assert (fake.values["aperture"], fake.values["imageformat"]) == ("f/8", "RAW")
    with pytest.raises(RigError, match="no shutterspeed matching camera_settings.exposure_s"):
        Gphoto2Camera(gp=fake_gphoto2(FakeCamera()), settings={"exposure_s": 2.0})


def test_failed_frame_write_is_a_rig_error_and_leaves_no_temporary_file(tmp_path: Path) -> None:
    source = tmp_path / "shot.cr2"
    source.write_bytes(b"raw")
    with pytest.raises(RigError, match="missing-dir"):
        copy_durably(source, tmp_path / "missing-dir" / "frame.cr2", move=True)
    (tmp_path / "out").mkdir()
    # the temporary name cannot be written
    temporary_name(tmp_path / "out" / "frame.cr2").mkdir()
    with pytest.raises(RigError, match=r"\.frame\.tmp\.cr2 is a folder"):
        write_durably(tmp_path / "out" / "frame.cr2", b"raw")
    assert source.exists() and not (tmp_path / "out" / "frame.cr2").exists()


def test_parse_shutter() -> None:
    assert parse_shutter("1/250") == pytest.approx(0.004)
    assert parse_shutter('2.5"') == 2.5
    assert parse_shutter("bulb") is None


# -- folder watch ---------------------------------------------------------------------------
def test_folder_watch_waits_until_the_new_file_stops_growing(tmp_path: Path) -> None:
    watch = tmp_path / "tether"
    watch.mkdir()
    (watch / "old.cr2").write_bytes(b"old")  # present before the shot: ignored
    now = [0.0]
    chunks = [b"b" * 100, b"c" * 100, b""]

    def trigger(stem: str) -> None:
        (watch / "IMG_0002.CR2").write_bytes(b"a" * 100)  # the app starts writing

    def sleep(seconds: float) -> None:
        now[0] += seconds
        if chunks:
            with open(watch / "IMG_0002.CR2", "ab") as handle:
                handle.write(chunks.pop(0))

    cam = FolderWatchCamera(
        watch, trigger, stable_s=1.0, poll_s=0.25, exposure_s=0.01, iso=100,
        clock=lambda: now[0], sleep=sleep,
    )  # fmt: skip
    frame = cam.capture(tmp_path / "raw", "f0003")
    assert frame.paths == (tmp_path / "raw" / "f0003.cr2",)
    assert frame.paths[0].read_bytes() == b"a" * 100 + b"b" * 100 + b"c" * 100
    assert not (watch / "IMG_0002.CR2").exists() and (watch / "old.cr2").exists()
    assert (frame.exposure_s, frame.iso) == (0.01, 100)


def test_folder_watch_from_a_profile_takes_exposure_from_camera_settings(tmp_path: Path) -> None:
    from drivers.registry import open_camera

    cam = open_camera(
        {
            "driver": "folder-watch",
            "folder": str(tmp_path),
            "settings": {"exposure_s": 0.05, "iso": 100, "aperture": 8},
        }
    )
    assert isinstance(cam, FolderWatchCamera)
    assert (cam.default_exposure_s, cam.default_iso) == (0.05, 100)


def test_folder_watch_times_out_when_nothing_arrives(tmp_path: Path) -> None:
    now = [0.0]

    def sleep(seconds: float) -> None:
        now[0] += seconds

    cam = FolderWatchCamera(
        tmp_path, lambda stem: None, timeout_s=5, clock=lambda: now[0], sleep=sleep
    )
    with pytest.raises(RigError, match="no complete new file appeared"):
        cam.capture(tmp_path / "raw", "f0")


# -- EXIF and hand-held import -------------------------------------------------------------------
def write_jpeg(
    path: Path,
    taken: str,
    exposure: float = 0.02,
    iso: int = 400,
    offset: str | None = None,
    subsec: str | None = None,
    serial: str | None = None,
) -> None:
    exif = Image.Exif()
    exif[0x0110] = "Test Cam"
    ifd = exif.get_ifd(0x8769)
    ifd[0x9003] = taken
    if offset:
        ifd[0x9011] = offset  # OffsetTimeOriginal
    if subsec:
        ifd[0x9291] = subsec  # SubSecTimeOriginal
    if serial:
        ifd[0xA431] = serial  # BodySerialNumber
    ifd[0x829A] = exposure
    ifd[0x8827] = iso
    Image.new("RGB", (8, 8)).save(path, exif=exif)


def test_exif_from_jpeg_and_from_a_real_dng(
    tmp_path: Path, shared_data: Path, caplog: pytest.LogCaptureFixture
) -> None:
    write_jpeg(tmp_path / "a.jpg", "2024:05:01 10:00:03")
    info = read_exif(tmp_path / "a.jpg")
    assert info.taken == datetime(2024, 5, 1, 10, 0, 3).astimezone()  # no offset: local time
    assert (info.exposure_s, info.iso, info.model) == (0.02, 400.0, "Test Cam")
    dng = read_exif(shared_data / "raw" / "colorchart.dng")
    assert dng.model == "Canon EOS Kiss X4"
    assert dng.exposure_s is None and dng.taken is None  # zero/empty fields are not guessed
    assert read_exif(tmp_path / "missing.cr2").taken is None
    (tmp_path / "not-an-image.nef").write_bytes(b"no EXIF here")
    with caplog.at_level(logging.WARNING):
        assert read_exif(tmp_path / "not-an-image.nef") == ExifInfo()
    assert not caplog.records  # a file without EXIF is no warning on the terminal


def test_exif_subseconds_serial_and_a_dng_with_tiff_ep_tags_in_ifd0(tmp_path: Path) -> None:
    write_jpeg(
        tmp_path / "a.jpg", "2024:05:01 10:00:03", offset="-05:00", subsec="25", serial="0123"
    )
    info = read_exif(tmp_path / "a.jpg")
    assert info.taken == datetime(2024, 5, 1, 15, 0, 3, 250000, tzinfo=timezone.utc)
    assert info.serial == "0123"
    # the simulated camera's DNG keeps exposure, ISO and serial in IFD0, as TIFF/EP allows
    mosaic = np.zeros((8, 8), np.uint16)
    write_dng(
        tmp_path / "s.dng",
        mosaic,
        black_level=0,
        white_level=4095,
        exposure_s=1 / 125,
        iso=1600,
        make="spectral-rig",
        model="Sim",
        serial="SIM-7",
        color_matrix=np.eye(3),
        as_shot_neutral=np.ones(3),
    )
    dng = read_exif(tmp_path / "s.dng")
    assert (dng.exposure_s, dng.iso, dng.serial, dng.model) == (1 / 125, 1600.0, "SIM-7", "Sim")


def test_frame_timestamps_are_utc_using_the_exif_offset(tmp_path: Path) -> None:
    write_jpeg(tmp_path / "a.jpg", "2024:05:01 10:00:03", offset="+02:00")
    frame = frame_from_files([tmp_path / "a.jpg"], None, None, "unknown")
    assert frame.timestamp == "2024-05-01T08:00:03+00:00"


def test_handheld_import_orders_by_exif_time_not_name(tmp_path: Path) -> None:
    shots = tmp_path / "card"
    shots.mkdir()
    write_jpeg(shots / "IMG_9999.jpg", "2024:05:01 10:00:01")  # counter wrapped: taken first
    write_jpeg(shots / "IMG_0001.jpg", "2024:05:01 10:00:05")
    write_jpeg(shots / "IMG_0002.jpg", "2024:05:01 10:00:09", iso=800)
    os.utime(shots / "IMG_9999.jpg", (2e9, 2e9))  # mtime disagrees; EXIF wins
    cam = HandheldImportCamera(shots, extensions=(".jpg",), frame_count=3)
    frames = [cam.capture(tmp_path / "raw", f"f{i}") for i in range(3)]
    assert [f.extra["source"] for f in frames] == [
        str(shots / "IMG_9999.jpg"),
        str(shots / "IMG_0001.jpg"),
        str(shots / "IMG_0002.jpg"),
    ]
    assert frames[2].iso == 800.0 and (shots / "IMG_0002.jpg").exists()
    with pytest.raises(RigError, match="all 3 files"):
        cam.capture(tmp_path / "raw", "f3")


def test_handheld_count_mismatch_is_an_error(tmp_path: Path) -> None:
    write_jpeg(tmp_path / "a.jpg", "2024:05:01 10:00:01")
    with pytest.raises(RigError, match="found 1 image files but the capture plan has 2"):
        match_files_to_frames([tmp_path / "a.jpg"], 2)
