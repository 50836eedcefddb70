"""`rig view`: the page's colour maths against colour-science, and the exported and served page
in a real browser (headless Debian Chromium driven by Playwright; skipped without them)."""

from __future__ import annotations

import shutil
import threading
import urllib.request
from pathlib import Path

import numpy as np
import pytest
import trimesh

from calibration.colorimetry import reflectance_to_srgb
from calibration.grid import DEFAULT_GRID
from reconstruct.outputs.export import write_reflectance_npz
from rig.cli import main
from rig.view.colour import illuminant_matrices
from rig.view.serve import make_server

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--no-first-run", "--disable-sync",
        "--enable-unsafe-swiftshader"]  # WebGL on the CPU: CI has no GPU


def _reflectances(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    wl = DEFAULT_GRID.wavelengths
    centre = rng.uniform(420, 680, (n, 1))
    return 0.1 + 0.8 * np.exp(-(((wl - centre) / rng.uniform(30, 120, (n, 1))) ** 2))


@pytest.fixture(scope="module")
def recon(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A reconstruction folder in the real formats: a sphere painted one orange reflectance
    (so a screenshot's colour is predictable), its 2-D start, and a ground truth."""
    session = tmp_path_factory.mktemp("view") / "sphere"
    recon = session / "recon"
    recon.mkdir(parents=True)
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    n = len(mesh.vertices)
    wl = DEFAULT_GRID.wavelengths
    orange = 0.05 + 0.85 / (1 + np.exp(-(wl - 590) / 12))
    reflectance = np.tile(orange, (n, 1))
    write_reflectance_npz(
        recon / "reflectance.npz", mesh.vertices, mesh.faces, mesh.vertex_normals, wl,
        reflectance, np.zeros((n, 8)), np.zeros((len(wl), 8)), np.ones(n, bool),
        {"initial_reflectance": reflectance * 0.8},
    )
    gt = session / "ground_truth"
    gt.mkdir()
    mesh.export(gt / "mesh.ply")
    np.save(gt / "reflectance.npy", reflectance + 0.05)
    return session


def encode_srgb(linear: np.ndarray) -> np.ndarray:
    """The sRGB transfer function on clipped linear values, as the page's JS applies it."""
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def test_page_colour_matrices_match_colour_science() -> None:
    r = _reflectances(50, 0)
    names = ["D65", "A", "FL11", "LED-B3"]
    for name, matrix in illuminant_matrices(names, DEFAULT_GRID).items():
        np.testing.assert_allclose(
            encode_srgb(r @ matrix), reflectance_to_srgb(r, DEFAULT_GRID, name), atol=1e-6
        )


def test_an_spd_file_is_an_illuminant(tmp_path: Path) -> None:
    csv = tmp_path / "warm-led.csv"
    wl = np.arange(380, 781, 5)
    csv.write_text("wavelength_nm,power\n" + "".join(
        f"{w},{np.exp(-((w - 600) / 90) ** 2):.6f}\n" for w in wl))
    matrices = illuminant_matrices([str(csv)], DEFAULT_GRID)
    assert list(matrices) == ["warm-led"]
    white = np.ones(DEFAULT_GRID.size) @ matrices["warm-led"]
    np.testing.assert_allclose(encode_srgb(white), 1.0, atol=2e-3)  # adapted white stays white


def test_bad_paths_are_one_line_errors(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["view", str(tmp_path), "--export", str(tmp_path / "v.html")]) == 2
    assert "holds no reflectance.npz" in capsys.readouterr().err
    assert main(["view", str(tmp_path), "--illuminant", "D99", "--export", "x.html"]) == 2


def test_server_binds_loopback_only(recon: Path) -> None:
    server = make_server("<html><title>t</title></html>", 0)
    try:
        assert server.server_address[0] == "127.0.0.1"
        threading.Thread(target=server.serve_forever, daemon=True).start()
        url = f"http://127.0.0.1:{server.server_address[1]}/"
        assert b"<title>t</title>" in urllib.request.urlopen(url, timeout=10).read()
    finally:
        server.shutdown()
        server.server_close()


@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed")
def test_exported_page_in_a_real_browser(recon: Path, tmp_path: Path) -> None:
    sync_playwright = pytest.importorskip("playwright.sync_api").sync_playwright
    page_file = tmp_path / "viewer.html"
    assert main(["view", str(recon), "--export", str(page_file)]) == 0
    assert "cdn" not in page_file.read_text().lower().split("<script>")[0]
    data = np.load(recon / "recon" / "reflectance.npz")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        page = browser.new_page(viewport={"width": 1200, "height": 700})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(page_file.as_uri())
        page.wait_for_function("window.viewerState !== undefined", timeout=60000)
        page.wait_for_timeout(1500)
        # the page's own colour maths agrees with colour-science
        js = np.array(page.evaluate("Array.from(window.viewerSrgb('A').slice(0, 3))"))
        np.testing.assert_allclose(js, reflectance_to_srgb(data["reflectance"][0], illuminant="A"),
                                   atol=2e-3)
        box = page.locator("#mesh").bounding_box()
        assert box is not None
        centre = (box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
        page.mouse.move(*centre, steps=5)  # hover first, as a person's pointer does
        page.wait_for_timeout(500)
        page.mouse.click(*centre)
        page.wait_for_function("window.selectedVertex !== undefined", timeout=20000)
        vertex = page.evaluate("window.selectedVertex")
        plotted = page.evaluate("document.getElementById('spectrum').data.map(t => t.y)")
        names = page.evaluate("document.getElementById('spectrum').data.map(t => t.name)")
        assert names == ["estimate", "2-D initial estimate", "truth"]
        np.testing.assert_allclose(plotted[0], data["reflectance"][vertex], atol=5e-4)
        np.testing.assert_allclose(plotted[2], data["reflectance"][vertex] + 0.05, atol=5e-4)
        d65 = _pixel(page, tmp_path / "d65.png", centre)
        page.select_option("#illuminant", "FL11")
        page.wait_for_timeout(800)
        fl11 = _pixel(page, tmp_path / "fl11.png", centre)
        browser.close()
    assert not errors
    expected = 255 * reflectance_to_srgb(data["reflectance"][vertex])
    # the mesh is lit mostly by ambient light in the page: its pixel keeps the vertex's hue
    assert d65[0] > d65[1] > d65[2] and np.abs(d65 - expected).max() < 60
    assert not np.allclose(d65, fl11, atol=3)  # the illuminant switch recolours the mesh


def _pixel(page: object, path: Path, at: tuple[float, float]) -> np.ndarray:
    from PIL import Image

    page.screenshot(path=str(path))  # type: ignore[attr-defined]
    image = np.asarray(Image.open(path).convert("RGB"), dtype=float)
    x, y = int(at[0]), int(at[1])
    return image[y - 3:y + 4, x - 3:x + 4].reshape(-1, 3).mean(axis=0)
