"""Decode: the one RAW reader and its users on the real Canon DNG, normalised linear camera
RGB, saturation masks, linear NPY frames, bad frames reported by name (skip or stop)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import rawpy

from core.config import from_mapping
from core.errors import RigError
from core.files import sha256_file
from core.manifest import FrameRecord, append_manifest
from reconstruct.frames import decode
from reconstruct.frames.decode import DecodeConfig, DecodeIndex, decode_raw, load_frame
from reconstruct.frames.raw import read_linear_rgb, read_mosaic
from rig.capture.frames import read_raw
from rig.wizard.reference_raw import region_rgb

BLACK, WHITE = 2056, 15000


def test_real_dng_is_normalised_linear_camera_rgb(shared_data: Path) -> None:
    path = shared_data / "raw" / "colorchart.dng"
    rgb, mask = decode_raw(path, "linear", 0.98)
    with rawpy.imread(str(path)) as raw:
        mosaic = raw.raw_image_visible.astype(float)
        colours = raw.raw_colors_visible.copy()
    assert rgb.shape[:2] == mosaic.shape and rgb.dtype == np.float32
    expected = np.maximum(mosaic - BLACK, 0) / (WHITE - BLACK)  # LibRaw clips below black
    for channel, code in ((0, 0), (1, 1), (2, 2)):
        sites = colours == code
        # at a site of its own colour the demosaiced value is the sample itself
        np.testing.assert_allclose(rgb[..., channel][sites], expected[sites], atol=2e-4)
    assert not mask.any()  # the chart was exposed below the white level (max 12128)


def test_raw_reader_gives_the_mosaic_and_its_levels(shared_data: Path) -> None:
    path = shared_data / "raw" / "colorchart.dng"
    mosaic = read_mosaic(path)
    with rawpy.imread(str(path)) as raw:
        values = raw.raw_image_visible.copy()
    assert np.array_equal(mosaic.values, values) and mosaic.values.dtype == np.uint16
    assert mosaic.colour_desc == "RGBG" and mosaic.colours.shape == values.shape
    assert mosaic.white == WHITE and np.all(mosaic.channel_black == BLACK)
    assert mosaic.pattern is not None and mosaic.pattern.shape == (2, 2)
    levels = mosaic.levels()
    np.testing.assert_allclose(levels, (values.astype(float) - BLACK) / (WHITE - BLACK), atol=1e-6)
    assert np.array_equal(mosaic.clipped(0.7), levels >= np.float32(0.7))
    same, rgb = read_linear_rgb(path, "linear")
    assert np.array_equal(same.values, values) and rgb.shape == (*values.shape, 3)


def test_capture_and_wizard_read_raw_through_the_one_reader(shared_data: Path) -> None:
    path = shared_data / "raw" / "colorchart.dng"
    mosaic = read_mosaic(path)
    data = read_raw(path)
    assert np.array_equal(data.values, mosaic.values)
    assert (data.black, data.white, data.period) == (BLACK, WHITE, 2)
    assert data.cfa_black is not None and np.all(data.cfa_black == BLACK)
    region = (100, 200, 140, 260)
    rgb, saturated = region_rgb(path, region)
    window = (slice(200, 260), slice(100, 140))
    level = (mosaic.values[window].astype(float) - BLACK) / (WHITE - BLACK)
    letters = np.array(list("RGBG"))[mosaic.colours[window]]
    np.testing.assert_allclose(rgb, [level[letters == c].mean() for c in "RGB"])
    assert not saturated


def test_saturation_mask_covers_clipped_neighbourhoods(shared_data: Path) -> None:
    path = shared_data / "raw" / "colorchart.dng"
    rgb, mask = decode_raw(path, "linear", 0.7)
    with rawpy.imread(str(path)) as raw:
        clipped = raw.raw_image_visible >= BLACK + 0.7 * (WHITE - BLACK)
    assert clipped.any()
    assert mask[clipped].all()
    assert mask.sum() <= 9 * clipped.sum()
    assert mask.mean() < 0.5


def _session(tmp_path: Path, frames: int = 3, flat: tuple[int, ...] = ()) -> Path:
    """Linear NPY frames; those in ``flat`` lack their colour axis (undecodable)."""
    root = tmp_path / "s"
    (root / "raw").mkdir(parents=True)
    (root / "session.yaml").write_text("rig: test\n")
    rng = np.random.default_rng(0)
    for k in range(frames):
        img = rng.integers(0, 4096, (8, 10) if k in flat else (8, 10, 3)).astype(np.uint16)
        img[0, 0] = 4095
        rel = f"raw/f{k}.npy"
        np.save(root / rel, img)
        append_manifest(root, FrameRecord(
            k, k, "white", rel, sha256_file(root / rel), 0.5, 400.0, "t",
            {"black_level": 64, "white_level": 4095}))
    return root


def test_linear_npy_frames_and_index(tmp_path: Path) -> None:
    root = _session(tmp_path)
    out = decode.run({"demosaic": "linear"}, root, root / "recon" / "decoded")
    index = DecodeIndex.load(out)
    assert [f.frame for f in index.frames] == [0, 1, 2] and not index.skipped
    image, sat = load_frame(out, index.frames[1])
    raw = np.load(root / "raw" / "f1.npy").astype(float)
    np.testing.assert_allclose(image, (raw - 64) / (4095 - 64) / (0.5 * 4), rtol=2e-3, atol=1e-4)
    assert sat[0, 0] and sat.sum() >= 1
    assert sorted(index.sfm_images) == [0, 1, 2]
    assert (out / "sfm" / index.sfm_images[0]).is_file()
    # resumable: nothing to do the second time
    decode.run({"demosaic": "linear"}, root, out)
    assert json.loads((root / "recon" / "timings.json").read_text())["decode"]["skipped"]


def test_bad_frames_are_named_and_skipped_or_stop(tmp_path: Path) -> None:
    root = _session(tmp_path, 4)
    (root / "raw" / "f1.npy").write_bytes(b"changed after capture")
    (root / "raw" / "f2.npy").unlink()
    out = decode.run({"on_bad_frame": "skip"}, root, root / "recon" / "decoded")
    index = DecodeIndex.load(out)
    assert index.skipped == {"raw/f1.npy": "hash mismatch", "raw/f2.npy": "missing"}
    assert [f.frame for f in index.frames] == [0, 3]
    with pytest.raises(RigError, match=r"raw/f1\.npy: hash mismatch; raw/f2\.npy: missing"):
        decode.run({"on_bad_frame": "stop"}, root, root / "recon" / "decoded2")


def test_corrupt_raw_with_matching_hash_is_reported(
    tmp_path: Path, make_session: Callable[..., Path]
) -> None:
    root = _session(tmp_path, 3)
    bad = root / "raw" / "broken.dng"
    bad.write_bytes(b"II*\x00 not really a raw file")
    append_manifest(root, FrameRecord(3, 3, "white", "raw/broken.dng", sha256_file(bad), 0.5,
                                      400.0, "t"))
    index = DecodeIndex.load(decode.run({}, root, root / "recon" / "decoded"))
    assert "raw/broken.dng" in index.skipped
    assert index.skipped["raw/broken.dng"].startswith("cannot be decoded")
    with pytest.raises(RigError, match=r"raw/broken\.dng"):
        decode.run({"on_bad_frame": "stop"}, root, root / "recon" / "decoded2")


def test_frames_decoded_in_parallel_keep_their_order(tmp_path: Path) -> None:
    """More frames than the decode threads run ahead, one undecodable early on: the index
    keeps the manifest's order and names the bad frame; a stop on it leaves no index."""
    root = _session(tmp_path, 12, flat=(2,))
    index = DecodeIndex.load(decode.run({}, root, root / "recon" / "decoded"))
    assert [f.frame for f in index.frames] == [k for k in range(12) if k != 2]
    assert index.skipped["raw/f2.npy"].startswith("cannot be decoded: expected an H x W x 3")
    with pytest.raises(RigError, match=r"raw/f2\.npy"):
        decode.run({"on_bad_frame": "stop"}, root, root / "recon" / "decoded2")
    assert not (root / "recon" / "decoded2" / "index.json").exists()


def test_config_is_checked() -> None:
    with pytest.raises(RigError, match="demosaic"):
        from_mapping(DecodeConfig, {"demosaic": "magic"}, "config", "decode")
    with pytest.raises(RigError, match="on_bad_frame"):
        from_mapping(DecodeConfig, {"on_bad_frame": "ignore"}, "config", "decode")
