"""Single-camera markers as ray constraints: the surface passes through each such marker's
ray, the face gets closer to the truth than solving with the marker missing, and rays are
taken into rest space by the stabilisation's head transforms."""

from __future__ import annotations

import numpy as np
import pytest

import lgi
from lgi.capture.camera import Rays
from lgi.capture.rays import solve_with_rays, to_rest_space
from lgi.capture.stabilize import Alignment
from lgi.capture.triangulation import triangulate
from lgi.lab.helmet import head_motion, helmet_cameras, make_helmet_take
from lgi.lab.sample import sample_dataset


@pytest.fixture(scope="module")
def sample_model():  # type: ignore[no-untyped-def]
    from lgi.lab.sample import make_sample

    s = make_sample(0)
    model = lgi.Model.build(sample_dataset(s), s.markers_rest, jaw=None)  # the front end alone
    frames = slice(60, 90)  # expressive frames
    return s.truth[frames], model, model.bundle_positions(s.truth[frames])


def test_single_view_markers_land_on_their_rays_and_beat_leaving_them_missing(sample_model) -> None:  # type: ignore[no-untyped-def]
    truth, model, bundles = sample_model
    cams = helmet_cameras(model.markers_rest)
    rng = np.random.default_rng(0)
    lost = rng.random(bundles.shape[:2]) < 0.1
    frames = bundles.copy()
    frames[lost] = np.nan
    # The true rays of the lost markers from the upper camera (a fault-free single view).
    d = bundles - cams[0].center
    d /= np.linalg.norm(d, axis=2, keepdims=True)
    o = np.broadcast_to(cams[0].center, d.shape).copy()
    o[~lost], d[~lost] = np.nan, np.nan
    out = solve_with_rays(model, frames, Rays(origins=o, directions=d), quiet=True)
    np.testing.assert_array_equal(out.on_ray, lost)
    assert np.nanmax(out.ray_distance) <= 1e-6 * model.diagonal
    plain = model.solve(frames, quiet=True)
    err_rays = np.linalg.norm(out.result.vertices - truth, axis=2).mean()
    err_missing = np.linalg.norm(plain.vertices - truth, axis=2).mean()
    assert err_rays < err_missing
    assert np.isnan(frames[lost]).all()  # the caller's frames are not modified


def test_rays_go_to_rest_space_with_the_head_transforms(sample_model) -> None:  # type: ignore[no-untyped-def]
    _, model, bundles = sample_model
    rest = model.markers_rest
    cams = helmet_cameras(rest)
    motion = head_motion(bundles.shape[0], rest, seed=2)
    take = make_helmet_take(bundles, cams, motion, seed=3, pixel_noise=0.0, mistrack=0.0)
    take.uv[:, ::7, 1] = np.nan  # every 7th marker seen by the upper camera only
    tri = triangulate(cams, take.uv)
    single = tri.views == 1
    assert single.sum() > 0
    # With the true head transforms, the true rest-space bundle lies exactly on its ray.
    al = Alignment(
        frames=bundles,
        rotations=motion.rotations,
        translations=motion.translations,
        inliers=np.ones(bundles.shape[:2], dtype=bool),
        rms=np.zeros(bundles.shape[0]),
    )
    rays = to_rest_space(tri.rays, al)
    v = bundles[single] - rays.origins[single]
    dd = rays.directions[single]
    off = np.linalg.norm(v - np.einsum("nd,nd->n", v, dd)[:, None] * dd, axis=1)
    assert off.max() <= 1e-9 * model.diagonal
    with pytest.raises(lgi.InputError, match="rays"):
        to_rest_space(Rays(tri.rays.origins[:2], tri.rays.directions[:2]), al)
