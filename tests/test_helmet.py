"""The synthetic helmet take and the whole front end on it: the rig sees the face, the head
motion is what it says, a fault-free take triangulates and stabilises back to its truth
exactly, and on the built-in sample the chain 2D tracks -> triangulate -> stabilise -> solve
stays close to solving from the true bundles while skipping stabilisation does not."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import lgi
from lgi.capture.stabilize import align, despike, stable_weights
from lgi.capture.triangulation import triangulate
from lgi.lab.helmet import head_motion, helmet_cameras, make_helmet_take
from lgi.lab.sample import sample_dataset


@pytest.fixture(scope="module")
def solved_sample():  # type: ignore[no-untyped-def]
    from lgi.lab.sample import make_sample

    s = make_sample(0)
    model = lgi.Model.build(sample_dataset(s), s.markers_rest, jaw=None)  # the front end alone
    return s, model, model.bundle_positions(s.truth)


def _layout() -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.uniform([-7, -9, 3], [7, 9, 12], size=(80, 3))


def test_rig_is_two_vertically_stacked_cameras_that_see_every_rest_marker() -> None:
    rest = _layout()
    cams = helmet_cameras(rest)
    assert len(cams) == 2
    c0, c1 = cams[0].center, cams[1].center
    assert abs(c0[0] - c1[0]) < 1e-9 and abs(c0[2] - c1[2]) < 1e-9 and c0[1] > c1[1]
    for c in cams:
        uv = c.project(rest)
        assert c.in_image(uv).all()


def test_head_motion_starts_at_rest_and_peaks_at_the_requested_angle() -> None:
    rest = _layout()
    m = head_motion(90, rest, seed=4, max_angle=15.0, max_shift=2.0)
    np.testing.assert_allclose(m.rotations[0], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(m.translations[0], 0.0, atol=1e-12)
    angles = np.degrees(Rotation.from_matrix(m.rotations).magnitude())
    assert angles.max() == pytest.approx(15.0, abs=1e-9)
    np.testing.assert_allclose(np.linalg.det(m.rotations), 1.0, atol=1e-12)
    again = head_motion(90, rest, seed=4)
    np.testing.assert_array_equal(again.rotations, m.rotations)


def test_fault_free_take_triangulates_and_stabilises_back_to_the_truth_exactly() -> None:
    rest = _layout()
    cams = helmet_cameras(rest)
    motion = head_motion(20, rest, seed=1)
    bundles = np.repeat(rest[None], 20, axis=0)
    take = make_helmet_take(
        bundles, cams, motion, seed=2, pixel_noise=0.0, occlusion=0.0, mistrack=0.0
    )
    np.testing.assert_array_equal(take.points, motion.apply(bundles))
    tri = triangulate(cams, take.uv)
    size = float(np.linalg.norm(np.ptp(rest, axis=0)))
    # Only the image border loses markers here (corners of the box leave the frame).
    np.testing.assert_array_equal(tri.missing, take.occluded.any(axis=2))
    assert tri.missing.mean() < 0.05
    assert np.nanmax(np.abs(tri.points - take.points)) <= 1e-6 * size
    al = align(tri.points, rest)
    assert np.nanmax(np.abs(al.frames - bundles)) <= 1e-6 * size
    np.testing.assert_allclose(al.rotations, motion.rotations, atol=1e-9)


def test_take_faults_match_the_requested_rates() -> None:
    rest = _layout()
    cams = helmet_cameras(rest)
    motion = head_motion(200, rest, seed=1)
    take = make_helmet_take(
        np.repeat(rest[None], 200, axis=0), cams, motion, seed=3, occlusion=0.05, mistrack=0.01
    )
    assert take.occluded.mean() == pytest.approx(0.05, abs=0.01)
    assert take.mistracked.mean() == pytest.approx(0.01, abs=0.003)
    assert np.isnan(take.uv[take.occluded]).all() and np.isfinite(take.uv[~take.occluded]).all()
    with pytest.raises(lgi.InputError, match="motion has 200 frames, bundles 3"):
        make_helmet_take(np.zeros((3, 80, 3)), cams, motion, seed=0)


def test_chain_on_the_sample_stays_near_the_true_bundles_and_stabilisation_is_essential(
    solved_sample,  # type: ignore[no-untyped-def]
) -> None:
    s, model, true_bundles = solved_sample
    cams = helmet_cameras(s.markers_rest)
    motion = head_motion(true_bundles.shape[0], s.markers_rest, seed=0)
    take = make_helmet_take(true_bundles, cams, motion, seed=1)
    tri = triangulate(cams, take.uv, max_error=3.0)
    assert tri.missing.mean() < 0.06
    stab = align(tri.points, s.markers_rest, stable_weights(tri.points, s.markers_rest))
    chain_frames, _ = despike(stab.frames)
    sigma = lgi.estimate_marker_noise(chain_frames)

    def err(frames, **kw):  # type: ignore[no-untyped-def]
        res = model.solve(frames, quiet=True, **kw)
        return float(np.linalg.norm(res.vertices - s.truth, axis=2).mean() / model.diagonal)

    truth_err = err(true_bundles)
    chain = err(chain_frames, marker_noise=sigma)
    unstabilised = err(tri.points, marker_noise=sigma)
    # Measured: 0.05 % of the diagonal from the true bundles, 0.15 % through the chain.
    assert truth_err < chain < 0.003
    assert unstabilised > 10 * chain
