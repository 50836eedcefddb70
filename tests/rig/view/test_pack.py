"""The viewer page's packed arrays: small, and rebuilt within half a quantisation step."""

from __future__ import annotations

import base64
import json
import zlib

import numpy as np
import trimesh

from calibration.basis import pca_basis
from calibration.grid import DEFAULT_GRID
from rig.view import pack
from rig.view.data import ViewData
from rig.view.page import payload


def inflate(text: str, dtype: str) -> np.ndarray:
    """What the page's JS does: base64 -> inflate -> byte planes back into values."""
    planes = np.frombuffer(zlib.decompress(base64.b64decode(text)), np.uint8)
    size = np.dtype(dtype).itemsize
    return np.ascontiguousarray(planes.reshape(size, -1).T).view(dtype).ravel()


def rebuild(packed: dict, basis: np.ndarray, n: int) -> np.ndarray:
    k = basis.shape[1]
    coefficients = inflate(packed["coefficients"], "<i2").reshape(n, k)
    residual = inflate(packed["residual"], "<i2").reshape(n, -1)
    return (coefficients * packed["coefficient_step"]) @ basis.T + residual * packed[
        "residual_step"
    ]


def scene(seed: int = 0) -> tuple[ViewData, np.ndarray]:
    """A sphere painted with mixtures of a few smooth reflectances, as the sim paints its scenes
    from a reflectance set; the estimate lies in an 8-D basis of those, the truth near it."""
    rng = np.random.default_rng(seed)
    wl = DEFAULT_GRID.wavelengths
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=0.05)
    n = len(mesh.vertices)
    paints = 0.1 + 0.7 * np.exp(-(((wl - rng.uniform(420, 680, (12, 1))) / 60) ** 2))
    weights = np.abs(np.sin(np.asarray(mesh.vertices) @ rng.normal(0, 60, (3, 12))))
    truth = (weights / weights.sum(axis=1, keepdims=True)) @ paints
    basis = pca_basis(paints, 8).B
    estimate = (truth + rng.normal(0, 0.01, truth.shape)) @ basis @ basis.T
    data = ViewData(
        name="sphere", vertices=np.asarray(mesh.vertices), faces=np.asarray(mesh.faces),
        wavelengths_nm=wl, reflectance=estimate, observed=np.ones(n, bool),
        initial=estimate * 0.9, truth=truth, basis=basis,
        cameras=np.zeros((0, 3)), lights=np.zeros((0, 3)),
    )
    return data, basis


def test_spectra_rebuild_within_half_a_step() -> None:
    data, basis = scene()
    n = len(data.vertices)
    for values in (data.reflectance, data.truth, data.reflectance * 7.5):
        assert values is not None
        packed = pack.spectra(values, basis)
        assert np.abs(rebuild(packed, basis, n) - values).max() <= packed["residual_step"] / 2
    # no basis: the residual carries everything
    packed = pack.spectra(data.reflectance, np.zeros((len(basis), 0)))
    assert np.abs(rebuild(packed, basis[:, :0], n) - data.reflectance).max() <= 1 / 4096


def test_positions_and_faces_round_trip() -> None:
    data, _ = scene()
    packed = pack.positions(data.vertices)
    q = inflate(packed["values"], "<u2").reshape(-1, 3)
    rebuilt = packed["origin"] + q * np.asarray(packed["step"])
    assert np.abs(rebuilt - data.vertices).max() <= 0.1 / 65535
    faces = inflate(pack.deflated(data.faces.astype("<i4")), "<i4").reshape(-1, 3)
    assert np.array_equal(faces, data.faces)


def test_page_data_is_at_most_60_bytes_a_vertex() -> None:
    data, _ = scene()
    size = len(json.dumps(payload(data, {})))
    assert size / len(data.vertices) <= 60, size / len(data.vertices)
