"""The detail weight (`lgi.plan.detail`): a solve keeping w of the dataset's detail between the
markers is `w * solved + (1 - w) * smooth`, the smooth part the biharmonic interpolation of the
solve's own marker positions (checked against `DisplacementInterpolation`, the baseline that
interpolates markers by that rule); the estimate from left-out markers is ~1 on the dataset's
own performance and low on a face whose motion the dataset does not hold."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import lgi
from lgi.errors import InputError
from lgi.lab.baselines import DisplacementInterpolation
from lgi.solve import gaps
from lgi.solve.detail import rest_positions


@pytest.fixture(scope="module")
def solved(sample, sample_dataset, noise_aware_sample):  # type: ignore[no-untyped-def]
    model, sigma = noise_aware_sample
    return sample_dataset, model, sample.performance[:40], sigma


def test_weight_zero_is_the_biharmonic_interpolation_of_the_solved_markers(solved, sample) -> None:  # type: ignore[no-untyped-def]
    data, model, frames, sigma = solved
    full = model.solve(frames, marker_noise=sigma, quiet=True)
    smooth = model.solve(frames, marker_noise=sigma, quiet=True, detail_weight=0.0)
    # The markers the solve interpolated: those given and the dropouts it filled
    # (`lgi.solve.gaps`).
    filled = gaps.filled(np.asarray(frames), rest_positions(model))[1]
    missing = np.asarray(full.missing) & ~filled
    # Where the solve put them, and then the surface followed beyond their noise.
    pulls = 0.0 if smooth.marker_pulls is None else np.asarray(smooth.marker_pulls)
    at = np.where(missing[..., None], np.nan, np.asarray(full.bundle_positions) + pulls)
    ref = DisplacementInterpolation(data, sample.markers_rest).solve(at, quiet=True)
    np.testing.assert_allclose(smooth.vertices, ref.vertices, rtol=0, atol=1e-9)
    # The present markers stay where the solve put them.
    np.testing.assert_allclose(smooth.bundle_residuals, full.bundle_residuals, rtol=0, atol=1e-9)
    assert (smooth.missing == full.missing).all() and smooth.choices.shapes.shape[0] == 40


def test_a_weight_blends_linearly_and_one_is_the_solve_bit_for_bit(solved) -> None:  # type: ignore[no-untyped-def]
    _, model, frames, sigma = solved
    full = model.solve(frames, marker_noise=sigma, quiet=True)
    one = model.solve(frames, marker_noise=sigma, quiet=True, detail_weight=1.0)
    zero = model.solve(frames, marker_noise=sigma, quiet=True, detail_weight=0)
    part = model.solve(frames, marker_noise=sigma, quiet=True, detail_weight=0.3)
    assert np.array_equal(one.vertices, full.vertices)
    np.testing.assert_allclose(
        part.vertices, 0.3 * full.vertices + 0.7 * zero.vertices, rtol=0, atol=1e-12
    )


def test_an_out_buffer_and_chunks_receive_the_blended_meshes(solved) -> None:  # type: ignore[no-untyped-def]
    _, model, frames, sigma = solved
    want = model.solve(frames, marker_noise=sigma, quiet=True, detail_weight=0.4)
    out = np.empty_like(want.vertices)
    got = model.solve(frames, marker_noise=sigma, quiet=True, detail_weight=0.4, out=out)
    assert got.vertices is out or np.shares_memory(got.vertices, out)
    np.testing.assert_array_equal(out, want.vertices)
    chunks = model.solve_iter(frames, chunk=16, marker_noise=sigma, quiet=True, detail_weight=0.4)
    np.testing.assert_array_equal(np.concatenate([c.vertices for c in chunks]), want.vertices)


def test_the_estimate_keeps_all_the_detail_of_the_datasets_own_performance(solved, sample) -> None:  # type: ignore[no-untyped-def]
    # The sample's performance is made from its dataset: whatever stretch of it is read, no
    # weight below 1 is clear of the noise of its left-out errors.
    _, model, _, sigma = solved
    for part in (slice(0, 40), slice(40, 80), slice(None)):
        w = lgi.estimate_detail_weight(sample.performance[part], model, marker_noise=sigma)
        assert w == 1.0, (part, w)


def test_the_estimate_drops_the_detail_of_a_smooth_motion_the_dataset_does_not_hold(
    solved,
) -> None:  # type: ignore[no-untyped-def]
    # Markers moved by a smooth field (an affine stretch plus a long wave), as large as the
    # performance's motion: the smooth interpolation is exact for it, the dataset's local
    # shapes are not, so the left-out markers ask for little of the detail.
    _, model, frames, _ = solved
    rest = model.bundle_positions(np.asarray(model.dataset.neutral, dtype=np.float64))
    size = float(np.ptp(rest, axis=0).max())
    motion = float(np.nanmean(np.linalg.norm(frames - rest[None], axis=2)))
    phase = np.linspace(0.0, 2.0 * np.pi, 12)[:, None, None]
    x = rest / size
    field = np.stack([x[:, 1] * x[:, 0], np.sin(2 * x[:, 0]) + x[:, 2], x[:, 1] ** 2], axis=1)
    field *= motion / np.linalg.norm(field, axis=1).mean()
    smooth_take = rest[None] + np.sin(phase) * field[None]
    w = lgi.estimate_detail_weight(smooth_take, model, frames_used=6)
    assert w < 0.5


@pytest.mark.parametrize("bad", [1.5, -0.1, float("nan"), "much"])
def test_bad_detail_weights_are_refused_naming_them(solved, bad) -> None:  # type: ignore[no-untyped-def]
    _, model, frames, _ = solved
    with pytest.raises(InputError, match="detail_weight: expected a number in"):
        model.solve(frames[:2], quiet=True, detail_weight=bad)


def test_a_take_with_too_few_markers_or_the_wrong_shape_is_refused(solved) -> None:  # type: ignore[no-untyped-def]
    _, model, frames, _ = solved
    sparse = frames[:3].copy()
    sparse[:, lgi._lgi.MIN_PRESENT_MARKERS :] = np.nan
    with pytest.raises(InputError, match="so none can be left out"):
        lgi.estimate_detail_weight(sparse, model)
    with pytest.raises(InputError, match="expected shape"):
        lgi.estimate_detail_weight(frames[:, :5], model)


def test_cli_solve_reads_the_detail_weight_from_the_take_or_takes_a_number(
    tmp_path: Path, sample, capsys
) -> None:  # type: ignore[no-untyped-def]
    from lgi.app import cli
    from pipeline_files import build_actor, write_c3d

    actor, model = build_actor(tmp_path, sample)
    take = tmp_path / "take.c3d"
    write_c3d(take, sample.performance[:20], actor.names, fps=60.0, units="cm")
    out = tmp_path / "o.npz"
    code = cli.main(["solve", str(model), str(take), "-o", str(out), "--detail-weight", "auto"])
    assert code == 0
    assert "detail weight " in capsys.readouterr().err
    code = cli.main(
        ["solve", str(model), str(take), "-o", str(tmp_path / "b.npz"), "--detail-weight", "2"]
    )
    assert code == 2
    assert "lgi: error: --detail-weight 2: must be a number in [0, 1]" in capsys.readouterr().err
