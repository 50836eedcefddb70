"""Folded vertices take the colour of settled neighbours that agree (optimise/pooling.py)."""

from __future__ import annotations

import numpy as np
import trimesh

from reconstruct.optimise.pooling import PoolingSettings, fold_angles, pooled_sources
from reconstruct.optimise.uncertainty import VertexUncertainty

RED = np.r_[np.full(15, 0.05), np.full(16, 0.7)]
BLUE = RED[::-1].copy()
GREEN = np.full(31, 0.3)


def crumpled_sphere(centre: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An icosphere painted red above the equator and blue below, with the vertices within
    0.15 of ``centre`` shaken off the surface; those left folded read green (a wrong colour)."""
    m = trimesh.creation.icosphere(5)
    X = np.array(m.vertices)
    rho = np.where(X[:, 2:] > 0, RED, BLUE)
    near = np.linalg.norm(X - centre / np.linalg.norm(centre), axis=1) < 0.15
    X[near] += 0.02 * np.random.default_rng(0).normal(size=(near.sum(), 3))
    rho[near & (fold_angles(X, m.faces)[0] > 5.0)] = GREEN
    return X, np.asarray(m.faces), rho


def test_a_smooth_surface_keeps_every_colour() -> None:
    m = trimesh.creation.icosphere(4)
    rho = np.where(m.vertices[:, 2:] > 0, RED, BLUE)
    source = pooled_sources(m.vertices, m.faces, rho, np.ones(len(rho), bool), PoolingSettings())
    assert np.array_equal(source, np.arange(len(rho)))


def test_folded_vertices_inside_one_paint_take_a_settled_neighbours_colour() -> None:
    X, F, rho = crumpled_sphere(np.array([1.0, 0.0, 0.6]))
    observed = np.random.default_rng(1).random(len(X)) > 0.05
    angle, _ = fold_angles(X, F)
    folded = observed & (angle > 5.0)
    assert folded.sum() > 20
    source = pooled_sources(X, F, rho, observed, PoolingSettings())
    moved = source != np.arange(len(X))
    assert moved.sum() > 0.5 * folded.sum()
    assert not moved[~folded].any()  # settled and unobserved vertices keep their own
    assert observed[source[moved]].all() and (angle[source[moved]] <= 5.0).all()
    assert np.array_equal(rho[source[moved]], np.broadcast_to(RED, (moved.sum(), 31)))


def test_among_two_paints_folded_vertices_keep_their_own() -> None:
    """Stripes narrower than the neighbourhood: no single paint to take."""
    X, F, _ = crumpled_sphere(np.array([1.0, 0.0, 0.3]))
    rho = np.where((np.floor(X[:, 2:] / 0.06) % 2) == 0, RED, BLUE)
    folded = fold_angles(X, F)[0] > 5.0
    assert folded.sum() > 20
    source = pooled_sources(X, F, rho, np.ones(len(X), bool), PoolingSettings())
    assert np.array_equal(source, np.arange(len(X)))


def test_off_keeps_every_colour() -> None:
    X, F, rho = crumpled_sphere(np.array([1.0, 0.0, 0.6]))
    source = pooled_sources(X, F, rho, np.ones(len(X), bool), PoolingSettings(max_fold_deg=0.0))
    assert np.array_equal(source, np.arange(len(X)))


def test_the_other_side_of_a_thin_part_lends_no_colour() -> None:
    """A slab 0.02 thick, red on top and blue below, its top crumpled in the middle: the
    bottom's vertices are nearer than most of the top's; the folded ones read green."""
    g = trimesh.creation.box(extents=(1.0, 1.0, 0.02)).subdivide().subdivide().subdivide()
    g = g.subdivide().subdivide()
    X = np.array(g.vertices)
    top = X[:, 2] > 0
    rho = np.where(top[:, None], RED, BLUE)
    middle = top & (np.linalg.norm(X[:, :2], axis=1) < 0.1)
    X[middle, 2] += 0.008 * np.random.default_rng(2).normal(size=middle.sum())
    folded = middle & (fold_angles(X, g.faces)[0] > 5.0)
    rho[folded] = GREEN
    source = pooled_sources(X, g.faces, rho, np.ones(len(X), bool), PoolingSettings())
    moved = source != np.arange(len(X))
    assert moved[middle].sum() > 0.5 * folded.sum() > 5
    assert np.array_equal(
        rho[source[moved & middle]], np.broadcast_to(RED, (moved[middle].sum(), 31))
    )


def test_the_uncertainty_moves_with_the_colour_and_the_position_stays() -> None:
    rng = np.random.default_rng(3)
    unc = VertexUncertainty(
        reflectance_std=rng.random((4, 31)),
        reflectance_low=rng.random((4, 31)),
        reflectance_high=rng.random((4, 31)),
        position_std_m=rng.random(4),
        alpha_cov=rng.random((4, 9, 9)),
        noise_std=0.01,
        dof=100,
    )
    moved = unc.colour_from(np.array([0, 0, 2, 2]))
    for name in ("reflectance_std", "reflectance_low", "reflectance_high", "alpha_cov"):
        before, after = getattr(unc, name), getattr(moved, name)
        assert np.array_equal(after[[0, 1, 2, 3]], before[[0, 0, 2, 2]])
    assert np.array_equal(moved.position_std_m, unc.position_std_m)
    assert moved.reflectance_std_gn is None
