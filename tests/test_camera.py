"""Cameras against OpenCV (`cv2.fisheye.projectPoints`, `cv2.projectPoints`, their
undistortPoints with tight criteria, and `cv2.FileStorage` reading what we write and writing
what we read), round trips across the whole image including the border, and triangulation
against known points: exact without noise, measured with 0.5 px noise, missing views reported."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import lgi
from lgi.capture.calibration import load_cameras, save_cameras
from lgi.capture.camera import FisheyeCamera, PinholeCamera, rodrigues
from lgi.capture.triangulation import triangulate

try:
    import cv2
except ImportError:  # the reference is a test dependency; without it only its tests skip
    cv2 = None  # type: ignore[assignment]

needs_cv2 = pytest.mark.skipif(
    cv2 is None, reason="opencv-python-headless (the cameras' reference) is not installed"
)
_COUNT, _EPS = 1, 2  # cv2.TERM_CRITERIA_COUNT, cv2.TERM_CRITERIA_EPS
# Tighter than 1e-14 and cv2.fisheye.undistortPoints flags points as not converged (-1e6).
TIGHT = (_COUNT | _EPS, 200, 1e-14)
RVEC = np.array([0.1, -0.2, 0.05])
TVEC = np.array([0.3, -0.1, 2.0])


def _fisheye(skew: float = 0.0, d: tuple[float, ...] = (0.05, -0.02, 0.004, -0.0005)):  # type: ignore[no-untyped-def]
    k = np.array([[600.0, skew, 640.0], [0, 590.0, 512.0], [0, 0, 1]])
    return FisheyeCamera(k, d, RVEC, TVEC, (1280, 1024))


def _pinhole():  # type: ignore[no-untyped-def]
    k = np.array([[900.0, 0, 640.0], [0, 910.0, 360.0], [0, 0, 1]])
    return PinholeCamera(k, (-0.2, 0.05, 0.001, -0.002, 0.01), RVEC, TVEC, (1280, 720))


def _grid(cam, n: int = 64):  # type: ignore[no-untyped-def]
    """Pixels over the whole image, its border included (the outermost pixel edges)."""
    w, h = cam.image_size
    u, v = np.meshgrid(np.linspace(-0.5, w - 0.5 - 1e-9, n), np.linspace(-0.5, h - 0.5 - 1e-9, n))
    return np.stack([u.ravel(), v.ravel()], axis=1)


def _cv_project(cam, x):  # type: ignore[no-untyped-def]
    rvec = cv2.Rodrigues(cam.R)[0]
    if cam.model == "fisheye":
        out, _ = cv2.fisheye.projectPoints(
            x.reshape(-1, 1, 3), rvec, cam.t, cam.K, cam.D, alpha=cam.alpha
        )
    else:
        out, _ = cv2.projectPoints(x.reshape(-1, 1, 3), rvec, cam.t, cam.K, cam.D)
    return out.reshape(-1, 2)


def _cv_normalized(cam, uv, criteria=TIGHT):  # type: ignore[no-untyped-def]
    p = uv.reshape(-1, 1, 2)
    if cam.model == "fisheye":
        return cv2.fisheye.undistortPoints(p, cam.K, cam.D, criteria=criteria).reshape(-1, 2)
    return cv2.undistortPoints(
        p, cam.K, cam.D, R=np.eye(3), P=np.eye(3), criteria=criteria
    ).reshape(-1, 2)


def _world_on_rays(cam, uv, depth: float = 1.7):  # type: ignore[no-untyped-def]
    rays = cam.unproject(uv)
    return rays.origins + depth * rays.directions


@needs_cv2
@pytest.mark.parametrize("make", [_fisheye, lambda: _fisheye(skew=1.5), _pinhole])
def test_projection_equals_opencv_to_1e_6_px_on_random_points_and_the_whole_image(make) -> None:  # type: ignore[no-untyped-def]
    cam = make()
    rng = np.random.default_rng(0)
    x = rng.normal(size=(4000, 3))
    ours = cam.project(x)
    inside = cam.in_image(ours)
    assert inside.sum() > 500
    ref = _cv_project(cam, x[inside])
    assert np.abs(ours[inside] - ref).max() <= 1e-6
    # The whole image, corners included: world points on our rays through a pixel grid.
    grid_points = _world_on_rays(cam, _grid(cam))
    assert np.isfinite(grid_points).all()
    assert np.abs(cam.project(grid_points) - _cv_project(cam, grid_points)).max() <= 1e-6


def test_points_behind_the_camera_and_nan_points_project_to_nan_and_shapes_are_kept() -> None:
    cam = _fisheye()
    behind = cam.center + cam.R.T @ np.array([0.1, 0.2, -1.0])
    got = cam.project(np.stack([behind, [np.nan, 0, 0], cam.center + cam.R.T @ [0, 0, 1]]))
    assert np.isnan(got[:2]).all() and np.isfinite(got[2]).all()
    assert cam.project(np.zeros((4, 5, 3))).shape == (4, 5, 2)


@needs_cv2
@pytest.mark.parametrize("make", [_fisheye, _pinhole])
def test_unprojection_equals_opencv_with_tight_criteria_and_round_trips_at_the_border(make) -> None:  # type: ignore[no-untyped-def]
    cam = make()
    uv = _grid(cam)
    ours = cam.normalized(uv)
    assert np.isfinite(ours).all()
    assert np.abs(ours - _cv_normalized(cam, uv)).max() <= 1e-12
    # Round trip in pixels: project(unproject(uv)) == uv over the whole image (<= 1e-6 px).
    back = cam.project(_world_on_rays(cam, uv))
    assert np.abs(back - uv).max() <= 1e-6
    # Rays are unit and start at the camera centre.
    rays = cam.unproject(uv)
    np.testing.assert_allclose(np.linalg.norm(rays.directions, axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(rays.origins, np.broadcast_to(cam.center, rays.origins.shape))


@needs_cv2
def test_opencv_default_pinhole_undistortion_is_weak_at_the_border_where_ours_round_trips() -> None:
    """Why un-projection is ours: OpenCV's default 5 iterations miss by a measurable amount
    at the border of a strongly distorted lens; our Newton inverse round-trips exactly."""
    cam = _pinhole()
    uv = _grid(cam)
    default = _cv_normalized(cam, uv, criteria=(_COUNT, 5, 0))
    d = np.concatenate([default, np.ones((len(uv), 1))], axis=1)
    cv_back = cam.project((d - cam.t) @ cam.R)
    assert np.abs(cv_back - uv).max() > 1e-3  # OpenCV's default: off by pixels' fractions
    assert np.abs(cam.project(_world_on_rays(cam, uv)) - uv).max() <= 1e-6


def test_fisheye_beyond_ninety_degrees_and_non_invertible_distortion_give_nan_rays() -> None:
    k = np.array([[200.0, 0, 640.0], [0, 200.0, 512.0], [0, 0, 1]])
    cam = FisheyeCamera(k, (0.0, 0.0, 0.0, 0.0), image_size=(1280, 1024))
    # Equidistant: r_px = f θ, so 400 px off centre is θ = 2 rad > 90°: no pinhole ray.
    d = cam.camera_directions(np.array([[640.0 + 400.0, 512.0], [640.0 + 100.0, 512.0]]))
    assert np.isnan(d[0]).all()
    np.testing.assert_allclose(d[1], [np.sin(0.5), 0, np.cos(0.5)], atol=1e-14)
    folded = FisheyeCamera(k, (-0.5, 0.0, 0.0, 0.0), image_size=(1280, 1024))
    # θ_d = θ - 0.5 θ³ peaks at 0.544 rad: beyond it the lens has no inverse.
    assert np.isnan(folded.camera_directions(np.array([[640.0 + 200.0 * 0.6, 512.0]]))).all()


def test_projection_jacobian_matches_central_differences() -> None:
    rng = np.random.default_rng(3)
    for cam in (_fisheye(skew=0.7), _pinhole()):
        x = _world_on_rays(cam, _grid(cam, 8), depth=2.3) + rng.normal(0, 1e-3, size=(64, 3))
        _, jac = cam.project_with_jacobian(x)
        h = 1e-6
        num = np.stack(
            [(cam.project(x + h * e) - cam.project(x - h * e)) / (2 * h) for e in np.eye(3)],
            axis=2,
        )
        np.testing.assert_allclose(jac, num, rtol=1e-5, atol=1e-4)


@given(
    d=st.tuples(*[st.floats(-0.05, 0.05)] * 4),
    xy=st.tuples(st.floats(-1.2, 1.2), st.floats(-1.2, 1.2)),
)
def test_fisheye_project_then_unproject_returns_the_same_ray(d, xy) -> None:  # type: ignore[no-untyped-def]
    cam = FisheyeCamera(np.array([[500.0, 0, 600], [0, 500, 500], [0, 0, 1]]), d)
    x = np.array([[xy[0], xy[1], 1.0]])
    back = cam.normalized(cam.project(x))
    np.testing.assert_allclose(back, x[:, :2], atol=1e-9)


@given(
    d=st.tuples(
        st.floats(-0.1, 0.1),
        st.floats(-0.02, 0.02),
        st.floats(-0.002, 0.002),
        st.floats(-0.002, 0.002),
        st.floats(-0.01, 0.01),
    ),
    xy=st.tuples(st.floats(-0.6, 0.6), st.floats(-0.6, 0.6)),
)
def test_pinhole_project_then_unproject_returns_the_same_ray(d, xy) -> None:  # type: ignore[no-untyped-def]
    cam = PinholeCamera(np.array([[800.0, 0, 640], [0, 800, 360], [0, 0, 1]]), d)
    x = np.array([[xy[0], xy[1], 1.0]])
    np.testing.assert_allclose(cam.normalized(cam.project(x)), x[:, :2], atol=1e-9)


def test_a_point_behind_both_cameras_is_reported_as_failed_not_invented() -> None:
    cams = _stereo_rig()
    # The upper camera's ray tilts up and the lower one's down: they diverge in front of the
    # rig and only meet behind it.
    uv = np.array([[[[640.0, 824.0], [640.0, 200.0]]]])
    tri = triangulate(cams, uv)
    assert tri.missing.all() and tri.failed.all() and "1 failed" in tri.summary()


def test_bad_camera_arguments_raise_input_errors_naming_the_argument() -> None:
    k = np.array([[500.0, 0, 600], [0, 500, 500], [0, 0, 1]])
    with pytest.raises(lgi.InputError, match="D: the fisheye model takes 4"):
        FisheyeCamera(k, (0.1, 0.2))
    with pytest.raises(lgi.InputError, match="K: focal lengths"):
        FisheyeCamera(np.diag([-1.0, 1, 1]), (0, 0, 0, 0))
    with pytest.raises(lgi.InputError, match="R: not a rotation"):
        PinholeCamera(k, (0, 0, 0, 0), R=np.diag([1.0, 1, -1]))
    with pytest.raises(lgi.InputError, match="t: expected"):
        PinholeCamera(k, (0, 0, 0, 0), t=(1, 2))
    with pytest.raises(lgi.InputError, match="image_size"):
        PinholeCamera(k, (0, 0, 0, 0), image_size=(0, 10))
    with pytest.raises(lgi.InputError, match="image_size"):
        PinholeCamera(k, (0, 0, 0, 0), image_size=("wide", 10))  # type: ignore[arg-type]
    with pytest.raises(lgi.InputError, match="D: not a numeric"):
        PinholeCamera(k, ("a", 0, 0, 0))
    with pytest.raises(lgi.InputError, match="no skew"):
        PinholeCamera(np.array([[500.0, 1, 600], [0, 500, 500], [0, 0, 1]]), (0, 0, 0, 0))
    with pytest.raises(lgi.InputError, match=r"points: expected shape \(\.\.\., 3\)"):
        _fisheye().project(np.zeros((4, 2)))


@needs_cv2
def test_rodrigues_equals_opencv() -> None:
    rng = np.random.default_rng(5)
    for r in rng.normal(size=(20, 3)):
        np.testing.assert_allclose(rodrigues(r), cv2.Rodrigues(r)[0], atol=1e-14)


@needs_cv2
@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_calibration_files_round_trip_and_opencv_filestorage_reads_them(
    tmp_path: Path, suffix
) -> None:  # type: ignore[no-untyped-def]
    cams = [_fisheye(skew=0.3), _pinhole()]
    path = tmp_path / f"rig{suffix}"
    save_cameras(path, cams)
    back = load_cameras(path)
    for a, b in zip(cams, back, strict=True):
        assert type(a) is type(b) and a.image_size == b.image_size
        for name in ("K", "D", "R", "t"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert int(fs.getNode("camera_count").real()) == 2
    assert fs.getNode("cam0_model").string() == "fisheye"
    np.testing.assert_array_equal(fs.getNode("cam0_K").mat(), cams[0].K)
    np.testing.assert_array_equal(fs.getNode("cam1_D").mat().ravel(), cams[1].D)
    assert int(fs.getNode("cam1_image_height").real()) == 720
    fs.release()


@needs_cv2
@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_calibration_written_by_opencv_filestorage_loads(tmp_path: Path, suffix) -> None:  # type: ignore[no-untyped-def]
    cam = _fisheye()
    path = tmp_path / f"cv{suffix}"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("camera_count", 1)
    fs.write("cam0_model", "fisheye")
    fs.write("cam0_image_width", 1280)
    fs.write("cam0_image_height", 1024)
    fs.write("cam0_K", cam.K)
    fs.write("cam0_D", cam.D.reshape(4, 1))
    fs.write("cam0_R", cam.R)
    fs.write("cam0_t", cam.t.reshape(3, 1))
    fs.release()
    (back,) = load_cameras(path)
    assert isinstance(back, FisheyeCamera) and back.image_size == (1280, 1024)
    for name in ("K", "D", "R", "t"):
        np.testing.assert_allclose(getattr(back, name), getattr(cam, name), rtol=1e-15)


def test_bad_calibration_files_name_the_file_and_what_is_wrong(tmp_path: Path) -> None:
    p = tmp_path / "rig.yaml"
    p.write_text("%YAML:1.0\n---\ncamera_count: 1\ncam0_model: fisheye\n")
    with pytest.raises(lgi.InputError, match=r"rig\.yaml: camera 0: missing cam0_image_width"):
        load_cameras(p)
    p.write_text("%YAML:1.0\ncamera_count: 1\n  oops\n")
    with pytest.raises(lgi.InputError, match=r"rig\.yaml, line 3"):
        load_cameras(p)
    j = tmp_path / "rig.json"
    j.write_text("{not json")
    with pytest.raises(lgi.InputError, match=r"rig\.json, line 1: not JSON"):
        load_cameras(j)
    with pytest.raises(lgi.InputError, match="cannot read"):
        load_cameras(tmp_path / "absent.yaml")
    save_cameras(p, [_fisheye()])
    p.write_text(p.read_text().replace("cam0_image_width: 1280", "cam0_image_width: wide"))
    with pytest.raises(lgi.InputError, match=r"rig\.yaml: camera 0: image_size"):
        load_cameras(p)
    p.write_text(p.read_text().replace("rows: 3\n   cols: 3", "rows: 2\n   cols: 3", 1))
    with pytest.raises(lgi.InputError, match=r"matrix cam0_K: 2x3 needs 6 values, got 9"):
        load_cameras(p)
    with pytest.raises(lgi.InputError, match=r"\.yaml, \.yml or \.json"):
        save_cameras(tmp_path / "rig.txt", [_fisheye()])


# --- triangulation ------------------------------------------------------------------------


def _stereo_rig():  # type: ignore[no-untyped-def]
    """Two fisheye cameras stacked vertically 8 units apart, 25 units in front of the origin,
    looking back at it (the helmet geometry at face scale)."""
    k = np.array([[500.0, 0, 640.0], [0, 500.0, 512.0], [0, 0, 1]])
    cams = []
    for y in (4.0, -4.0):
        c = np.array([0.0, y, 25.0])
        fwd = -c / np.linalg.norm(c)
        right = np.cross([0.0, 1.0, 0.0], fwd)
        right /= np.linalg.norm(right)
        down = np.cross(fwd, right)
        r = np.stack([right, down, fwd])
        cams.append(FisheyeCamera(k, (0.02, -0.01, 0.002, 0.0), r, -r @ c, (1280, 1024)))
    return cams


def _face_points(rng: np.random.Generator, f: int, b: int) -> np.ndarray:
    """Points in a face-sized box (20 units tall)."""
    return rng.uniform([-7, -10, -2], [7, 10, 6], size=(f, b, 3))


def test_noiseless_triangulation_recovers_points_to_1e_6_of_the_face_size() -> None:
    rng = np.random.default_rng(0)
    cams = _stereo_rig()
    x = _face_points(rng, 5, 60)
    uv = np.stack([c.project(x) for c in cams], axis=2)
    tri = triangulate(cams, uv)
    size = 20.0
    assert (tri.views == 2).all() and not tri.missing.any()
    assert np.abs(tri.points - x).max() <= 1e-6 * size
    assert np.nanmax(tri.reprojection_error) <= 1e-6


def test_half_pixel_noise_gives_a_measured_3d_error_and_rms_near_the_noise() -> None:
    rng = np.random.default_rng(1)
    cams = _stereo_rig()
    x = _face_points(rng, 20, 60)
    uv = np.stack([c.project(x) for c in cams], axis=2)
    noisy = uv + rng.normal(0, 0.5, size=uv.shape)
    tri = triangulate(cams, noisy)
    err = np.linalg.norm(tri.points - x, axis=2)
    # Two views, 3 unknowns, 4 residuals: the RMS of the per-view errors has 1 dof per marker.
    assert 0.1 < float(np.median(tri.reprojection_error)) < 0.6
    # 0.5 px at ~25 units and f = 500: ~0.025 units across, a few times that in depth.
    assert 0.005 < float(np.median(err)) < 0.2
    # Gauss-Newton beats the linear initialisation alone (it is the reprojection minimum).
    lin = triangulate(cams, noisy, iterations=0)
    assert np.mean(lin.reprojection_error) > np.mean(tri.reprojection_error)


def test_markers_seen_by_under_two_cameras_are_nan_reported_and_single_views_are_rays() -> None:
    rng = np.random.default_rng(2)
    cams = _stereo_rig()
    x = _face_points(rng, 2, 10)
    uv = np.stack([c.project(x) for c in cams], axis=2)
    uv[0, 3, 1] = np.nan  # seen by camera 0 only
    uv[1, 4] = np.nan  # unseen
    tri = triangulate(cams, uv)
    assert tri.views[0, 3] == 1 and tri.views[1, 4] == 0
    assert tri.missing[0, 3] and tri.missing[1, 4] and tri.missing.sum() == 2
    assert "1 seen by one camera" in tri.summary() and "1 unseen" in tri.summary()
    # The ray of the single-view marker passes through the true point.
    o, d = tri.rays.origins[0, 3], tri.rays.directions[0, 3]
    v = x[0, 3] - o
    assert np.linalg.norm(v - (v @ d) * d) <= 1e-9
    assert np.isnan(tri.rays.origins[0, 0]).all()


def test_a_mistracked_sample_is_rejected_and_with_three_views_its_bad_view_dropped() -> None:
    rng = np.random.default_rng(4)
    cams = _stereo_rig()
    third = FisheyeCamera(
        cams[0].K, cams[0].D, rodrigues([0, 0.3, 0]) @ cams[1].R, None, (1280, 1024)
    )
    third = FisheyeCamera(
        third.K, third.D, third.R, -third.R @ np.array([8.0, 0, 24.0]), (1280, 1024)
    )
    x = _face_points(rng, 1, 8)
    uv2 = np.stack([c.project(x) for c in cams], axis=2)
    uv2[0, 2, 0] += 25.0
    tri = triangulate(cams, uv2, max_error=3.0)
    assert tri.rejected[0, 2] and tri.missing[0, 2] and tri.rejected.sum() == 1
    cams3 = [*cams, third]
    uv3 = np.stack([c.project(x) for c in cams3], axis=2)
    uv3[0, 2, 0] += 25.0
    tri3 = triangulate(cams3, uv3, max_error=3.0)
    assert not tri3.rejected.any()
    assert np.abs(tri3.points - x).max() <= 1e-7


def test_triangulate_checks_its_arguments() -> None:
    cams = _stereo_rig()
    with pytest.raises(lgi.InputError, match=r"uv: expected shape \(F, B, 2, 2\)"):
        triangulate(cams, np.zeros((3, 4, 3, 2)))
    with pytest.raises(lgi.InputError, match="cameras"):
        triangulate([], np.zeros((3, 4, 0, 2)))
    with pytest.raises(lgi.InputError, match="max_error"):
        triangulate(cams, np.zeros((1, 1, 2, 2)), max_error=-1)
