"""Continuity of the solve under a tiny move of every marker (issue 34's perturbation test):
the recommended call moves the surface by a bounded multiple of the markers' move; the paper's
mode (`fit=False`) jumps, and only in frames where a bundle's choice changed. Measured on ICT
captures by scripts/perturbation_results.py (docs/results.md)."""

from __future__ import annotations

import numpy as np
import pytest

import lgi

FRAMES = 60


@pytest.fixture(scope="module")
def moved(sample, sample_dataset):  # type: ignore[no-untyped-def]
    """The sample's jaw model, 60 frames of its performance, the same frames with every marker
    moved by 1 µm scaled to the sample's size (a random direction each, seeded) and the
    move's length."""
    model = lgi.Model.build(sample_dataset, sample.markers_rest)
    frames = np.asarray(sample.performance[:FRAMES])
    move = 1e-4 * model.diagonal / 14.0  # 1 µm on a face of 14 cm
    rng = np.random.default_rng(1)
    d = rng.normal(size=frames.shape)
    d /= np.linalg.norm(d, axis=2, keepdims=True)
    return model, frames, frames + move * d, move


def _gain(model, a, b, move, **opts):  # type: ignore[no-untyped-def]
    ra = model.solve(a, temporal=False, quiet=True, **opts)
    rb = model.solve(b, temporal=False, quiet=True, **opts)
    gain = np.linalg.norm(ra.vertices - rb.vertices, axis=2).max(axis=1) / move
    changed = (np.asarray(ra.choices.shapes) != np.asarray(rb.choices.shapes)).any(axis=(1, 2))
    return gain, changed


def test_a_tiny_move_of_every_marker_moves_the_recommended_surface_by_a_bounded_multiple(
    moved,
) -> None:  # type: ignore[no-untyped-def]
    model, a, b, move = moved
    gain, _ = _gain(model, a, b, move, marker_noise=0.02 * model.diagonal / 14.0)
    # Measured 3.2 x at most on the sample, 10.5 x on ICT captures: a Lipschitz-like bound.
    assert gain.max() <= 20.0, gain.max()


def test_the_paper_mode_jumps_only_in_frames_where_a_choice_changed(moved) -> None:  # type: ignore[no-untyped-def]
    model, a, b, move = moved
    gain, changed = _gain(model, a, b, move, fit=False)
    jumps = gain > 100.0
    # The discontinuity is real (a 1 µm move moves the surface by over 100 µm somewhere) and
    # it is the choice's: every such frame changed a bundle's tet.
    assert jumps.any()
    assert np.all(changed[jumps])
    # Where no choice changed, the paper's mode is as continuous as interpolation is.
    assert np.all(gain[~changed] <= 20.0), gain[~changed]
