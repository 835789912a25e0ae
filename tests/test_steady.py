"""A take's frames read together: dropouts filled from the take's motion or the marker's
neighbours (`lgi.solve.gaps`) and the dataset's detail kept steady across frames
(`lgi.solve.steady`)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lgi
from lgi.solve import gaps, steady
from lgi.solve.detail import rest_positions
from lgi.solve.motion import read_motion


def _rigid_take(
    frames: int = 60, markers: int = 12, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """Markers carried by one nonlinear translation, marker 0 also drifting linearly in time:
    every fill the module makes is exact on it (closed form)."""
    rng = np.random.default_rng(seed)
    rest = rng.normal(size=(markers, 3))
    t = np.arange(frames, dtype=float)
    carry = np.stack([np.sin(t / 5.0), np.cos(t / 7.0) ** 2, 0.1 * t], axis=1)  # (F, 3)
    x = rest[None] + carry[:, None]
    x[:, 0] += np.outer(t, [0.01, -0.02, 0.005])
    return x, rest


def test_a_dropout_is_filled_exactly_where_the_marker_moves_with_its_neighbours() -> None:
    x, rest = _rigid_take()
    given_ = x.copy()
    given_[20:26, 0] = np.nan  # a 6-frame dropout of the drifting marker
    given_[40, 3] = np.nan
    out, done = gaps.filled(given_, rest)
    np.testing.assert_allclose(out, x, atol=1e-12)
    assert done.sum() == 7 and done[20:26, 0].all() and done[40, 3]
    assert np.isnan(given_[20, 0, 0])  # the caller's frames are not touched


def test_a_long_gap_a_marker_never_seen_and_a_frame_without_neighbours_stay_missing() -> None:
    x, rest = _rigid_take(frames=100)
    x[10 : 10 + gaps.MAX_GAP + 1, 0] = np.nan
    x[:, 5] = np.nan
    near = gaps.nearest(rest)[1]
    x[70, 1] = np.nan
    x[70, near] = np.nan
    out, done = gaps.filled(x, rest)
    assert not done[:, 0].any() and not done[:, 5].any() and not done[70, 1]
    assert np.isnan(out[10, 0]).all() and np.isnan(out[70, 1]).all()


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    start=st.integers(1, 150),
    size=st.integers(1, 60),
)
def test_a_chunk_filled_with_its_context_equals_the_take_filled_whole(
    seed: int, start: int, size: int
) -> None:
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(200, 8, 3)).cumsum(axis=0)
    lost = rng.random((200, 8)) < 0.15
    x[lost] = np.nan
    rest = rng.normal(size=(8, 3))
    # By the neighbours, and by the whole take's motion (read once, as `solve_iter` reads it).
    motion = read_motion(x, 0.0, 3)
    for by in (None, motion):
        whole, done = gaps.filled(x, rest, by)
        stop = min(200, start + size)
        lo, hi = max(0, start - gaps.CONTEXT), min(200, stop + gaps.CONTEXT)
        part, part_done = gaps.filled(x[lo:hi], rest, by)
        np.testing.assert_array_equal(part[start - lo : stop - lo], whole[start:stop])
        np.testing.assert_array_equal(part_done[start - lo : stop - lo], done[start:stop])
        seen = ~lost
        np.testing.assert_array_equal(whole[seen], x[seen])  # what was seen is kept


def _moving_take(frames: int, markers: int, rank: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Markers moving in `rank` smooth random directions of the whole face (noise-free): a
    marker moves with markers anywhere on it, not with its nearest ones."""
    rng = np.random.default_rng(seed)
    rest = rng.normal(size=(markers, 3))
    t = np.arange(frames, dtype=float)[:, None]
    paths = np.sin(t / rng.uniform(3.0, 12.0, rank) + rng.uniform(0.0, 6.0, rank))  # (F, rank)
    x = rest[None] + (paths @ rng.normal(size=(rank, markers * 3))).reshape(frames, markers, 3)
    return x, rest


def test_a_dropout_its_neighbours_do_not_follow_is_filled_exactly_from_the_takes_motion() -> None:
    x, rest = _moving_take(300, 20, 4, seed=3)
    given_ = x.copy()
    given_[100:106, 2] = np.nan
    given_[200, 7] = given_[200, 11] = np.nan
    # With the take's motion read whole, the fill is exact.
    exact = read_motion(x, 0.0, 4)
    out, done = gaps.filled(given_, rest, exact)
    np.testing.assert_allclose(out, x, atol=1e-9)
    assert done.sum() == 8 and np.isnan(given_[100, 2, 0])
    # Read from the take with its gaps (`fill_motion`: the gaps pull the directions a
    # little), within 1e-3 of a motion ~1 across; the neighbours' fill misses by 0.59.
    motion = gaps.fill_motion(given_, rest, 0.0)
    assert motion is not None and motion.rank == 4
    read = gaps.filled(given_, rest, motion)[0]
    by_neighbours = gaps.filled(given_, rest)[0]
    assert np.abs(read - x).max() < 1e-3
    assert np.abs(by_neighbours - x)[done].max() > 0.5


def test_a_take_whose_markers_move_with_their_neighbours_only_is_filled_by_the_neighbours() -> None:
    # Eight clusters of markers, each carried by its own random walk: 24 directions, more than
    # a fill reads, and each marker exactly where its cluster puts it.
    rng = np.random.default_rng(4)
    centres = 10.0 * rng.normal(size=(8, 3))
    rest = (centres[:, None] + 0.1 * rng.normal(size=(8, 5, 3))).reshape(40, 3)
    walks = rng.normal(size=(300, 8, 3)).cumsum(axis=0)
    x = rest[None] + np.repeat(walks, 5, axis=1)
    given_ = x.copy()
    given_[rng.random((300, 40)) < 0.02] = np.nan
    assert gaps.fill_motion(given_, rest, 0.0) is None
    out, done = gaps.filled(given_, rest)
    np.testing.assert_allclose(out[done], x[done], atol=1e-9)


def test_reading_the_fill_holds_out_the_same_runs_each_time_and_leaves_the_take_alone() -> None:
    x, rest = _moving_take(200, 12, 3, seed=5)
    x += 0.01 * np.random.default_rng(5).normal(size=x.shape)
    x[np.random.default_rng(6).random((200, 12)) < 0.03] = np.nan
    before = x.copy()
    first, second = gaps.fill_motion(x, rest, 0.01), gaps.fill_motion(x, rest, 0.01)
    np.testing.assert_array_equal(x, before)
    assert first is not None and second is not None
    np.testing.assert_array_equal(first.directions, second.directions)
    # A take too short to hold out the runs is filled by the neighbours.
    assert gaps.fill_motion(x[:5], rest, 0.01) is None


@pytest.mark.parametrize("width", [steady.SIGMA_FRAMES, steady.LOCAL_SIGMA_FRAMES])
def test_steadying_keeps_every_marker_where_the_solve_put_it_and_spreads_a_one_frame_flip(
    sample, sample_model, width
) -> None:  # type: ignore[no-untyped-def]
    res = sample_model.solve(sample.performance[:30], temporal=False, quiet=True)
    v = np.array(res.vertices)
    p = sample_model.bundle_positions(v)
    flip = v.copy()
    bump = np.zeros(v.shape[1:])
    bump[:, 2] = 0.3 * np.sin(3.0 * v[15, :, 0])  # not a motion the markers' interpolation makes
    flip[15] += bump  # a flip at one frame
    flip[15] -= steady.surface_interpolator(sample_model).interpolate(
        sample_model.bundle_positions(flip[15:16]) - p[15:16]
    )[0]  # ... that leaves the markers where they were
    np.testing.assert_allclose(sample_model.bundle_positions(flip), p, atol=1e-9)
    out = steady.steadied(sample_model, flip.copy(), p, width=width)
    np.testing.assert_allclose(sample_model.bundle_positions(out), p, atol=1e-9)
    jump = np.abs(flip[15] - v[15]).max()
    left = np.abs(out[15] - steady.steadied(sample_model, v.copy(), p, width=width)[15]).max()
    # A Gaussian of `width` frames, cut at 4 widths, keeps its centre's share of a one-frame
    # excursion at its frame (0.399 at 1 frame, 0.570 at 0.7).
    reach = int(4.0 * width + 0.5)
    kernel = np.exp(-0.5 * (np.arange(-reach, reach + 1) / width) ** 2)
    assert jump > 0.1 and left == pytest.approx(jump / kernel.sum(), rel=0.02)


def test_steadying_refuses_a_filter_wider_than_its_chunks_reach(sample, sample_model) -> None:  # type: ignore[no-untyped-def]
    res = sample_model.solve(sample.performance[:5], temporal=False, quiet=True)
    v, p = np.array(res.vertices), np.array(res.bundle_positions)
    for width in (0.0, 1.5):
        with pytest.raises(ValueError, match="width"):
            steady.steadied(sample_model, v.copy(), p, width=width)


@pytest.mark.parametrize("frames", [1, 2, 70])
def test_a_surface_steadied_with_its_corrective_left_as_misses_is_the_surface_steadied(
    sample, sample_model, frames
) -> None:  # type: ignore[no-untyped-def]
    res = sample_model.solve(sample.performance[:frames], temporal=False, quiet=True)
    v, p = np.array(res.vertices), np.array(res.bundle_positions)
    misses = np.random.default_rng(frames).normal(0.0, 0.05, p.shape)
    interp = np.asarray(steady.surface_interpolator(sample_model).matrix)
    # u + S m = v: the surface less the interpolation of the misses over it.
    u = v - np.einsum("vb,fbd->fvd", interp, misses)
    want = steady.steadied(sample_model, v.copy(), p)
    got = steady.steadied(sample_model, u, p, misses=misses)
    assert np.abs(got - want).max() < 1e-12
    with pytest.raises(ValueError, match="whole take"):
        steady.steadied(sample_model, u, p, misses=misses, before=(v[:1], p[:1]))


def test_a_steady_solve_with_local_fits_adds_their_corrective_once_to_round_off(
    sample, sample_model, monkeypatch
) -> None:  # type: ignore[no-untyped-def]
    from lgi.solve.model import Model

    frames = np.array(sample.performance[:40])
    opts = {"marker_noise": 0.02, "local_fits": True, "quiet": True, "repair": False}
    fused = sample_model.solve(frames, **opts)
    # The corrective made over the mesh first, then the steady's own: the same surface.
    monkeypatch.setattr(
        Model, "_finish_steadied", lambda self, res, fr, o: (self._finish(res, fr, o), None)
    )
    twice = sample_model.solve(frames, **opts)
    assert np.abs(np.asarray(fused.vertices) - np.asarray(twice.vertices)).max() < 1e-9
    np.testing.assert_allclose(fused.bundle_positions, twice.bundle_positions, atol=1e-9)
    np.testing.assert_allclose(fused.bundle_residuals, twice.bundle_residuals, atol=1e-9)


@pytest.mark.parametrize("block", [1, 5, 64])
def test_a_take_steadied_in_chunks_equals_it_steadied_whole_bit_for_bit(
    sample, sample_model, block, monkeypatch
) -> None:  # type: ignore[no-untyped-def]
    res = sample_model.solve(sample.performance[:40], temporal=False, quiet=True)
    v, p = np.array(res.vertices), np.array(res.bundle_positions)
    monkeypatch.setattr(steady, "_BLOCK", block)
    whole = steady.steadied(sample_model, v.copy(), p)
    r = steady.RADIUS
    for a, b in ((10, 25), (0, 7), (33, 40), (12, 13)):
        before = (v[max(a - r, 0) : a], p[max(a - r, 0) : a]) if a else None
        after = (v[b : b + r], p[b : b + r]) if b < 40 else None
        part = steady.steadied(
            sample_model, v[a:b].copy(), p[a:b], first=a, before=before, after=after
        )
        np.testing.assert_array_equal(part, whole[a:b])  # blocks by frame number: bit for bit
    # The markers stay where the solve put them.
    np.testing.assert_allclose(sample_model.bundle_positions(whole), p, atol=1e-9)


def test_a_take_with_dropouts_solves_the_same_in_chunks_reports_its_gaps_missing_and_pops_less(
    sample, sample_model
) -> None:  # type: ignore[no-untyped-def]
    frames = np.array(sample.performance[:60])
    frames[18:22, 3] = frames[29, 7] = frames[30:33, 0] = np.nan  # across chunk edges of 10
    frames[45, 5, 1] = np.nan  # a row with one NaN is missing, as the core reads it
    lost = np.isnan(frames).any(axis=2)
    whole = sample_model.solve(frames, quiet=True)
    parts = list(sample_model.solve_iter(frames, chunk=10, quiet=True))
    np.testing.assert_array_equal(np.concatenate([p.vertices for p in parts]), whole.vertices)
    np.testing.assert_array_equal(whole.missing, lost)
    want = gaps.filled(frames, rest_positions(sample_model))[1]
    assert want[45, 5] and np.array_equal(whole.filled, want)
    assert not whole.bundle_residuals[lost].any()
    # Every present marker is still interpolated exactly (the paper's mode).
    pos = sample_model.bundle_positions(whole.vertices)
    np.testing.assert_allclose(pos[~lost], frames[~lost], atol=1e-6)
    # Against each frame solved alone: closer to the truth on the frames with a dropout.
    truth = np.asarray(sample.truth[:60])
    alone = sample_model.solve(frames, temporal=False, quiet=True)
    rows = lost.any(axis=1)

    def err(r: lgi.SolveResult) -> float:
        return float(np.linalg.norm(r.vertices[rows] - truth[rows], axis=2).mean())

    assert err(whole) < 0.95 * err(alone)


def test_a_solve_says_the_rank_of_the_motion_that_filled_its_dropouts_whole_and_in_chunks(
    sample, sample_model
) -> None:  # type: ignore[no-untyped-def]
    frames = np.array(sample.performance)
    frames[np.random.default_rng(7).random(frames.shape[:2]) < 0.02] = np.nan
    # The fill read directly (`fill_motion`, at the exact interpolation's noise 0).
    motion = gaps.fill_motion(frames, rest_positions(sample_model), 0.0)
    assert motion is not None
    whole = sample_model.solve(frames, quiet=True)
    assert whole.filled is not None and whole.filled.any()
    assert whole.fill_rank == motion.rank
    parts = list(sample_model.solve_iter(frames, chunk=50, quiet=True))
    assert {p.fill_rank for p in parts if p.filled.any()} == {motion.rank}
    # Nothing to fill, or each frame alone: no rank.
    clean = sample_model.solve(sample_model.bundle_positions(sample.truth[:40]), quiet=True)
    assert clean.fill_rank is None and not clean.filled.any()
    assert sample_model.solve(frames, quiet=True, steady=False).fill_rank is None


def test_a_take_filled_by_its_neighbours_solves_with_no_rank(sample_model) -> None:  # type: ignore[no-untyped-def]
    # Three frames: too short to hold out the runs a motion's rank is chosen on.
    x = np.array(sample_model.markers_rest)[None].repeat(3, axis=0)
    x[1, 4] = np.nan
    r = sample_model.solve(x, quiet=True)
    assert r.filled is not None and r.filled[1, 4] and r.fill_rank is None


def test_rest_positions_give_each_marker_its_nearest_neighbours(sample_model) -> None:  # type: ignore[no-untyped-def]
    rest = rest_positions(sample_model)
    near = gaps.nearest(rest)
    d = np.linalg.norm(rest[:, None] - rest[None], axis=2)
    np.fill_diagonal(d, np.inf)
    brute = np.sort(d, axis=1)[:, : near.shape[1]]
    np.testing.assert_allclose(np.take_along_axis(d, near, axis=1), brute)
    assert isinstance(sample_model, lgi.Model)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    sigma=st.floats(1e-3, 0.5),
)
def test_a_marker_further_than_five_sigma_is_pulled_by_its_excess_and_no_other(
    seed: int, sigma: float
) -> None:
    rng = np.random.default_rng(seed)
    positions = rng.normal(size=(6, 9, 3))
    miss = rng.normal(size=(6, 9, 3)) * rng.uniform(0.0, 6.0 * sigma, size=(6, 9, 1))
    frames = positions + miss
    frames[2, 4] = np.nan
    frames[3, 1, 2] = np.nan  # a sample with one coordinate missing is missing
    pulls = steady.marker_pulls(frames, positions, sigma)
    assert pulls is not None
    for f in range(6):
        for b in range(9):
            d = np.linalg.norm(miss[f, b])
            lost = (f, b) in ((2, 4), (3, 1))
            # Closed form: the excess over 5 sigma, along the miss.
            want = 0.0 if lost or d <= 5.0 * sigma else (d - 5.0 * sigma) / d
            np.testing.assert_allclose(pulls[f, b], want * miss[f, b], rtol=1e-12, atol=1e-15)
    assert steady.marker_pulls(frames, positions, None) is None
    assert steady.marker_pulls(frames, positions, 0.0) is None


def test_a_steady_surface_meets_each_marker_within_five_sigma_whole_and_in_chunks(
    sample, sample_model
) -> None:  # type: ignore[no-untyped-def]
    frames = np.array(sample.performance[:60])
    sigma = 0.002  # below the sample's own misses at some markers: some samples are pulled
    whole = sample_model.solve(frames, marker_noise=sigma, quiet=True)
    pulls = whole.marker_pulls
    assert pulls is not None and np.linalg.norm(pulls, axis=2).max() > 0.0
    seen = ~np.isnan(frames).any(axis=2)
    # The surface's markers are where the solve put them plus their pulls ...
    on_surface = sample_model.bundle_positions(whole.vertices)
    np.testing.assert_allclose(on_surface, whole.bundle_positions + pulls, atol=1e-9)
    # ... so every marker the take has is within 5 sigma of the surface.
    reach = np.linalg.norm(frames - on_surface, axis=2)[seen]
    assert reach.max() <= 5.0 * sigma + 1e-9
    # Residuals are still the solve's (before the pull), which the findings read.
    far = np.linalg.norm(frames - whole.bundle_positions, axis=2)
    np.testing.assert_allclose(whole.bundle_residuals[seen], far[seen], atol=1e-12)
    parts = list(sample_model.solve_iter(frames, chunk=16, marker_noise=sigma, quiet=True))
    np.testing.assert_array_equal(np.concatenate([p.vertices for p in parts]), whole.vertices)
    np.testing.assert_array_equal(np.concatenate([p.marker_pulls for p in parts]), pulls)
    # With local fits (whose corrective the steady pass adds with the pulls): the same reach.
    fits = sample_model.solve(frames, marker_noise=sigma, local_fits=True, quiet=True)
    assert fits.marker_pulls is not None
    on_fits = sample_model.bundle_positions(fits.vertices)
    np.testing.assert_allclose(on_fits, fits.bundle_positions + fits.marker_pulls, atol=1e-9)
    assert np.linalg.norm(frames - on_fits, axis=2)[seen].max() <= 5.0 * sigma + 1e-9
    # ... steadied by the local fits' narrower filter, whole and in chunks alike.
    fits_parts = sample_model.solve_iter(
        frames, chunk=16, marker_noise=sigma, local_fits=True, quiet=True
    )
    in_chunks = np.concatenate([p.vertices for p in fits_parts])
    assert np.abs(in_chunks - np.asarray(fits.vertices)).max() < 1e-9
    # Each frame alone: nothing is pulled.
    assert (
        sample_model.solve(frames, marker_noise=sigma, steady=False, quiet=True).marker_pulls
        is None
    )
