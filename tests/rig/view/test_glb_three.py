"""`rig export --glb` in three.js (GLTFLoader, WebGL in headless Chromium): the file loads, its
spectra arrive as custom attributes, and its linear COLOR_0 renders to the viewer's sRGB.

three.js is not part of the project: the test runs when the npm package `three` is in
``node_modules/three`` at the repository root (`npm install --no-save three`) or in the folder
``$THREE_JS_DIR``, and is skipped otherwise."""

from __future__ import annotations

import functools
import os
import threading
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest
import trimesh
from test_view import ARGS, CHROMIUM

from calibration.colorimetry import reflectance_to_srgb
from calibration.grid import DEFAULT_GRID
from reconstruct.outputs.export import write_ply, write_reflectance_npz
from rig.cli import main

ROOT = Path(__file__).resolve().parents[3]
THREE = Path(os.environ.get("THREE_JS_DIR") or ROOT / "node_modules" / "three")

PAGE = """<!DOCTYPE html><html><head><meta charset="utf-8">
<script type="importmap">{"imports": {"three": "./three/build/three.module.js",
  "three/addons/": "./three/examples/jsm/"}}</script></head>
<body style="margin:0"><canvas id="c" width="200" height="200"></canvas>
<script type="module">
import * as THREE from "three";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";
const gltf = await new GLTFLoader().loadAsync("model.glb");
let mesh = null; gltf.scene.traverse(o => { if (o.isMesh) mesh = o; });
mesh.material = new THREE.MeshBasicMaterial({vertexColors: true});  // unlit: pixel = colour
const renderer = new THREE.WebGLRenderer({canvas: document.getElementById("c"),
  preserveDrawingBuffer: true});
const scene = new THREE.Scene(); scene.add(mesh);
const camera = new THREE.PerspectiveCamera(30, 1, 0.01, 10);
camera.position.set(0, 0, 0.4); camera.lookAt(0, 0, 0);
renderer.render(scene, camera);
const gl = renderer.getContext(), pixel = new Uint8Array(4);
gl.readPixels(100, 100, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);
const g = mesh.geometry;
window.result = {count: g.attributes.position.count, names: Object.keys(g.attributes),
  r550: Array.from(g.attributes._reflectance_550.array.slice(0, 5)), pixel: Array.from(pixel)};
</script></body></html>"""


@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed")
@pytest.mark.skipif(not (THREE / "build" / "three.module.js").is_file(),
                    reason="three.js is not installed: `npm install --no-save three` or set "
                    "THREE_JS_DIR")
def test_glb_in_three_js_renders_the_viewers_colour(tmp_path: Path) -> None:
    sync_playwright = pytest.importorskip("playwright.sync_api").sync_playwright
    recon = tmp_path / "sphere" / "recon"
    recon.mkdir(parents=True)
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    n = len(mesh.vertices)
    wl = DEFAULT_GRID.wavelengths
    orange = 0.05 + 0.85 / (1 + np.exp(-(wl - 590) / 12))
    reflectance = np.tile(orange, (n, 1))
    args = (mesh.vertices, mesh.faces, mesh.vertex_normals)
    write_ply(recon / "mesh.ply", *args, reflectance, wl)
    write_reflectance_npz(recon / "reflectance.npz", *args, wl, reflectance,
                          np.zeros((n, 8)), np.zeros((len(wl), 8)), np.ones(n, bool))
    site = tmp_path / "site"
    site.mkdir()
    assert main(["export", str(recon), "--glb", str(site / "model.glb")]) == 0
    (site / "index.html").write_text(PAGE)
    (site / "three").symlink_to(THREE, target_is_directory=True)
    handler = functools.partial(SimpleHTTPRequestHandler, directory=str(site))
    server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
            page = browser.new_page()
            errors: list[str] = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(f"http://127.0.0.1:{server.server_address[1]}/index.html")
            page.wait_for_function("window.result !== undefined", timeout=60000)
            result = page.evaluate("window.result")
            browser.close()
    finally:
        server.shutdown()
        server.server_close()
    assert not errors
    assert result["count"] == n
    assert {"position", "normal", "color", "_reflectance_400", "_reflectance_700"} <= set(
        result["names"]
    )
    np.testing.assert_allclose(result["r550"], orange[15], atol=1e-6)
    # three.js turns the linear COLOR_0 into sRGB on output: the viewer's colour under D65
    expected = 255 * reflectance_to_srgb(orange, DEFAULT_GRID, "D65")
    assert np.abs(np.array(result["pixel"][:3]) - expected).max() <= 3, (result, expected)
