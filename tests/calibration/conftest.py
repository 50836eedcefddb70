"""Fixtures shared by the estimation tests: the default basis and the default bulb's responses."""

from __future__ import annotations

import numpy as np
import pytest

from calibration import defaults
from calibration.basis import SpectralBasis, default_basis
from calibration.estimation import response_matrices


@pytest.fixture(scope="module")
def basis() -> SpectralBasis:
    return default_basis()


@pytest.fixture(scope="module")
def responses() -> np.ndarray:
    """``A_k`` of the built-in camera under the default RGBCW bulb's illuminations (3, 3, N_λ)."""
    ch = defaults.rgbcw_channel_spds()
    spds = [defaults.illumination_spd(v, ch) for v in defaults.default_illuminations().values()]
    return response_matrices(defaults.camera_sensitivity(), spds)
