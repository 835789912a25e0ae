"""How much of its surfaces a solve makes: the markers alone (`Model.solve_markers`, what a
take's readings read) and none at all (the core's `surface="none"`, under local fits, whose
surface replaces the core's). Each must give what the whole solve gives."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from lgi.errors import InputError
from lgi.solve.local import local_pieces


@pytest.fixture(scope="module")
def take(noise_aware_sample: Any, sample: Any) -> tuple[Any, np.ndarray, float]:
    """The sample's default build (jaw rig), 12 frames of its performance with a marker
    missing in two of them, and its marker noise."""
    model, sigma = noise_aware_sample
    frames = np.array(sample.performance[:12], dtype=np.float64)
    frames[3, 5] = np.nan
    frames[7, 11] = np.nan
    return model, frames, float(sigma)


def test_the_markers_alone_are_the_whole_solves_marker_positions_bit_for_bit(take: Any) -> None:
    model, frames, sigma = take
    for fit in (None, "unbounded"):
        whole = model.solve(frames, temporal=False, marker_noise=sigma, fit=fit, quiet=True)
        alone = model.solve_markers(frames, marker_noise=sigma, fit=fit)
        assert np.asarray(alone.vertices).shape == (12, 0, 3)
        for field in (
            "bundle_positions",
            "bundle_residuals",
            "missing",
            "fit_weights",
            "jaw_theta",
        ):
            assert np.array_equal(
                np.asarray(getattr(alone, field)), np.asarray(getattr(whole, field))
            ), field
        assert np.array_equal(np.asarray(alone.choices.tets), np.asarray(whole.choices.tets))


def test_a_solve_without_a_surface_reports_its_targets_and_every_piece_as_a_fit(
    take: Any,
) -> None:
    model, frames, sigma = take
    whole = model.core.solve(frames, marker_noise=sigma, jaw="auto")
    none = model.core.solve(frames, marker_noise=sigma, jaw="auto", surface="none")
    missing = np.isnan(frames).any(axis=2)
    assert np.array_equal(np.asarray(none.missing), missing)
    assert np.asarray(none.choices.fit)[~missing].all()
    assert (np.asarray(none.choices.tets) == -1).all()
    pos, ref = np.asarray(none.bundle_positions), np.asarray(whole.bundle_positions)
    # The sewn surface passes through the noise-aware targets to the residual pass's round-off.
    assert np.abs(pos[~missing] - ref[~missing]).max() <= 1e-9 * model.diagonal
    assert np.isnan(pos[missing]).all()
    assert np.array_equal(np.asarray(none.fit_weights), np.asarray(whole.fit_weights))
    assert np.array_equal(np.asarray(none.jaw_theta), np.asarray(whole.jaw_theta))
    assert np.array_equal(np.asarray(none.marker_corrections), np.asarray(whole.marker_corrections))


def test_local_fits_made_from_the_targets_alone_equal_those_made_from_the_sewn_surface(
    take: Any,
) -> None:
    model, frames, sigma = take
    got = model.solve(frames, marker_noise=sigma, local_fits=True, steady=False, quiet=True)
    sewn = model.core.solve(frames, marker_noise=sigma, jaw="auto")
    want = local_pieces(model).surface(sewn)
    assert np.abs(np.asarray(got.vertices) - want).max() <= 1e-9 * model.diagonal


def test_a_surface_that_is_not_one_of_the_three_is_refused_in_our_words(take: Any) -> None:
    model, frames, _ = take
    with pytest.raises(InputError, match="surface must be 'mesh', 'markers' or 'none', got 'all'"):
        model.core.solve(frames, surface="all")
    # A buffer of the wrong size is still refused where the surface is made.
    with pytest.raises(InputError, match="out"):
        model.core.solve(frames, out=np.empty((12, 3, 3)), surface="none")
