"""Tests of the shipped sample against independent references (brute force, scipy, closed form)."""

from __future__ import annotations

from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from lgi.errors import DatasetError, DatasetFileError, InputError
from lgi.lab.sample import Sample, describe, load_sample, make_sample, save_sample
from lgi.solve.jaw import JawRig

F64 = NDArray[np.float64]


@pytest.fixture(scope="module")
def sample() -> Sample:
    return make_sample()


@pytest.fixture(scope="module")
def small() -> Sample:
    return make_sample(seed=3, resolution=60, num_frames=40)


# ------------------------------------------------------------------------------------------
# Independent references.


def point_triangle_distances(p: F64, a: F64, b: F64, c: F64) -> F64:
    """Distance from p to every triangle (a[i], b[i], c[i]): plane if inside, else edges."""
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    h = np.einsum("ij,ij->i", p - a, n)
    q = p - h[:, None] * n
    inside = np.ones(a.shape[0], dtype=bool)
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(v - u, q - u), n) >= 0

    def seg(u: F64, v: F64) -> F64:
        d = v - u
        t = np.clip(np.einsum("ij,ij->i", p - u, d) / np.einsum("ij,ij->i", d, d), 0, 1)
        return np.linalg.norm(p - (u + t[:, None] * d), axis=1)

    edge = np.minimum(np.minimum(seg(a, b), seg(b, c)), seg(c, a))
    return np.where(inside, np.abs(h), edge)


def boundary_loops(triangles: NDArray[np.int64]) -> list[list[int]]:
    """Boundary edges (used by one triangle) chained into loops of vertices."""
    count = Counter(
        tuple(sorted(e)) for t in triangles for e in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0]))
    )
    nxt: dict[int, list[int]] = defaultdict(list)
    for (u, v), k in count.items():
        if k == 1:
            nxt[u].append(v)
            nxt[v].append(u)
    seen: set[int] = set()
    loops = []
    for start in nxt:
        if start in seen:
            continue
        loop, prev, cur = [start], -1, start
        seen.add(start)
        while True:
            step = [w for w in nxt[cur] if w != prev]
            prev, cur = cur, step[0]
            if cur == start:
                break
            seen.add(cur)
            loop.append(cur)
        loops.append(loop)
    return loops


def reference_truth(s: Sample, f: int) -> F64:
    """The module's documented truth formula, with scipy rotations for the jaw."""
    jaw = np.any(s.shape_jaw_theta != 0, axis=1)
    w = s.truth_weights[f]
    shapes = s.shapes.astype(np.float64)
    wr = s.wrinkles.astype(np.float64)
    pre = s.neutral.copy()
    for k in np.nonzero(~jaw & (w > 0))[0]:
        pre += w[k] * (shapes[k] - wr[k]) + w[k] ** 1.5 * wr[k]
    theta = w[jaw] @ s.shape_jaw_theta[jaw]
    rot = Rotation.from_euler("YX", [theta[1], theta[0]])  # intrinsic: Ry(lateral) @ Rx(open)
    moved = rot.apply(pre - s.jaw_pivot) + s.jaw_pivot + np.array([0.0, 0.0, theta[2]])
    return pre + s.jaw_weights[:, None] * (moved - pre)


def mirror_index(positions: F64) -> NDArray[np.int64]:
    """Index of each vertex's mirror image across x = 0 (the face is built symmetric)."""
    key = {(round(x, 6), round(y, 6)): i for i, (x, y, _) in enumerate(positions)}
    return np.array([key[(round(-x, 6), round(y, 6))] for x, y, _ in positions])


# ------------------------------------------------------------------------------------------
# Determinism and sizes.


def test_same_seed_gives_bit_identical_arrays(small: Sample) -> None:
    again = make_sample(seed=3, resolution=60, num_frames=40)
    for name in ("neutral", "triangles", "shapes", "markers_rest", "truth", "truth_weights"):
        np.testing.assert_array_equal(getattr(small, name), getattr(again, name))
    np.testing.assert_array_equal(small.performance, again.performance)  # NaNs in same places
    assert small.names == again.names and small.marker_names == again.marker_names


def test_different_seed_changes_markers_and_performance(small: Sample) -> None:
    other = make_sample(seed=4, resolution=60, num_frames=40)
    assert not np.array_equal(small.markers_rest, other.markers_rest)
    assert not np.array_equal(small.truth_weights, other.truth_weights)
    np.testing.assert_array_equal(small.neutral, other.neutral)  # the face itself is fixed


def test_default_sizes_and_consistent_shapes(sample: Sample) -> None:
    v, s, b, f = sample.num_vertices, sample.num_shapes, sample.num_markers, sample.num_frames
    assert v >= 10_000 and s >= 30 and 90 <= b <= 130 and f >= 120
    t = sample.triangles.shape[0]
    assert sample.triangles.shape == (t, 3) and sample.triangles.dtype == np.int64
    assert sample.uvs.shape == (v, 2) and sample.uv_triangles.shape == (t, 3)
    assert sample.shapes.shape == (s, v, 3) and sample.shapes.dtype == np.float32
    assert sample.wrinkles.shape == (s, v, 3)
    assert sample.performance.shape == (f, b, 3) and sample.truth.shape == (f, v, 3)
    assert sample.truth_weights.shape == (f, s) and sample.jaw_theta.shape == (f, 3)
    assert sample.jaw_weights.shape == (v,) and sample.shape_jaw_theta.shape == (s, 3)
    assert len(sample.names) == s == len(set(sample.names))
    assert len(sample.marker_names) == b == len(set(sample.marker_names))
    size = np.ptp(sample.neutral, axis=0)
    assert 13.0 < size[0] < 15.0 and 15.0 < size[1] < 17.0


# ------------------------------------------------------------------------------------------
# Mesh.


def test_mesh_is_manifold_with_consistent_winding(sample: Sample) -> None:
    tri = sample.triangles
    assert np.array_equal(np.unique(tri), np.arange(sample.num_vertices))  # no stray vertex
    directed = Counter((int(t[i]), int(t[(i + 1) % 3])) for t in tri for i in range(3))
    assert max(directed.values()) == 1  # each directed edge once: consistent orientation
    undirected = Counter(tuple(sorted(e)) for e in directed)
    assert max(undirected.values()) <= 2
    boundary_degree = Counter(v for e, k in undirected.items() if k == 1 for v in e)
    assert set(boundary_degree.values()) == {2}  # no pinched boundary vertex
    p = sample.neutral
    area = np.linalg.norm(
        np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]]), axis=1
    )
    assert area.min() > 1e-4


def test_mouth_and_eyes_are_holes(sample: Sample) -> None:
    loops = boundary_loops(sample.triangles)
    assert len(loops) == 4  # outer border, mouth, two eyes
    outer = max(loops, key=len)
    assert np.ptp(sample.neutral[outer, 0]) > 13.0 and np.ptp(sample.neutral[outer, 1]) > 15.0
    inner = [lp for lp in loops if lp is not outer]
    centres = np.array([sample.neutral[lp, :2].mean(axis=0) for lp in inner])
    order = np.argsort(centres[:, 0])
    right_eye, mouth, left_eye = centres[order]
    assert abs(mouth[0]) < 0.1 and mouth[1] == pytest.approx(-3.4, abs=0.1)
    assert right_eye[0] < -2.0 and left_eye[0] > 2.0 and right_eye[1] > 2.0 < left_eye[1]
    mouth_loop = inner[order[1]]
    w = sample.jaw_weights[mouth_loop]
    assert w.min() == 0.0 and w.max() == 1.0  # upper and lower lip are separate sides


def test_uvs_are_one_planar_chart(sample: Sample) -> None:
    np.testing.assert_array_equal(sample.uv_triangles, sample.triangles)
    uv = sample.uvs
    assert uv.min() >= 0.0 and uv.max() <= 1.0
    t = sample.uv_triangles
    e1, e2 = uv[t[:, 1]] - uv[t[:, 0]], uv[t[:, 2]] - uv[t[:, 0]]
    signed = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    assert signed.min() > 0  # all positively oriented: the map is injective, one chart
    # Holes are the only missing area of the unit square (no overlap, no gap elsewhere).
    assert 0.9 < 0.5 * signed.sum() < 1.0


# ------------------------------------------------------------------------------------------
# Markers.


def test_markers_lie_on_the_neutral_surface(sample: Sample) -> None:
    p, tri = sample.neutral, sample.triangles
    bary = sample.marker_barycentrics
    assert bary.min() >= 0.0 and np.allclose(bary.sum(axis=1), 1.0)
    corners = p[tri[sample.marker_triangles]]
    a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
    for i, m in enumerate(sample.markers_rest):
        own = point_triangle_distances(m[None], corners[i, 0:1], corners[i, 1:2], corners[i, 2:3])
        assert own[0] < 1e-9
        assert point_triangle_distances(m[None], a, b, c).min() < 1e-9
        assert np.linalg.norm(p - m, axis=1).min() > 1e-3  # not sitting on a vertex


def test_markers_cover_the_face_on_both_lips(sample: Sample) -> None:
    m = sample.markers_rest
    assert m[:, 1].min() < -6.5 and m[:, 1].max() > 6.5 and np.ptp(m[:, 0]) > 11.0
    w = sample.jaw_weights[sample.triangles[sample.marker_triangles]].mean(axis=1)
    near_mouth = np.abs(m[:, 1] + 3.4) < 0.6
    upper = near_mouth & (m[:, 1] > -3.4) & (np.abs(m[:, 0]) < 2.0)
    lower = near_mouth & (m[:, 1] < -3.4) & (np.abs(m[:, 0]) < 2.0)
    assert upper.sum() >= 5 and lower.sum() >= 5
    assert w[upper].max() < 0.3 and w[lower].min() > 0.7  # on either side of the cut
    assert w[upper & (np.abs(m[:, 0]) < 0.5)].max() == 0.0
    assert w[lower & (np.abs(m[:, 0]) < 0.5)].min() == 1.0
    for side in (-1.0, 1.0):
        around_eye = np.hypot(m[:, 0] - side * 3.1, m[:, 1] - 2.6) < 2.2
        assert around_eye.sum() >= 6


# ------------------------------------------------------------------------------------------
# Shapes.


def test_jaw_shapes_are_rigid_motions_about_the_pivot(sample: Sample) -> None:
    k = sample.names.index("jawOpen")
    theta = sample.shape_jaw_theta[k]
    assert theta[0] == pytest.approx(np.deg2rad(25.0)) and theta[1] == theta[2] == 0.0
    rigid = np.nonzero(sample.jaw_weights == 1.0)[0]
    chin = rigid[sample.neutral[rigid, 1] < -6.0]
    assert chin.size > 100
    rot = Rotation.from_euler("X", theta[0])
    expected = rot.apply(sample.neutral[chin] - sample.jaw_pivot) + sample.jaw_pivot
    moved = sample.neutral[chin] + sample.shapes[k, chin]
    np.testing.assert_allclose(moved, expected, atol=1e-5)  # float32 storage
    # The stored shape keeps distances up to float32 rounding; its float64 source exactly.
    i, j = chin[0], chin[-1]
    d0 = np.linalg.norm(sample.neutral[i] - sample.neutral[j])
    assert abs(np.linalg.norm(moved[0] - moved[-1]) - d0) < 1e-5
    exact = JawRig(sample.jaw_pivot, sample.jaw_weights).skin(sample.neutral, theta)
    assert abs(np.linalg.norm(exact[i] - exact[j]) - d0) < 1e-9
    others = ~np.isin(sample.names, ["jawOpen", "jawLeft", "jawRight", "jawForward"])
    assert np.all(sample.shape_jaw_theta[others] == 0.0)
    assert np.all(sample.shape_jaw_theta[~others].any(axis=1))


def test_jaw_weights_split_the_lips_and_hold_chin_and_brow(sample: Sample) -> None:
    w, p = sample.jaw_weights, sample.neutral
    assert w.min() == 0.0 and w.max() == 1.0
    assert np.all(w[p[:, 1] < -5.5] == 1.0) and np.all(w[p[:, 1] > 1.0] == 0.0)
    centre = np.abs(p[:, 0]) < 0.3
    assert np.all(w[centre & (p[:, 1] > -3.4) & (p[:, 1] < -2.0)] == 0.0)  # upper lip
    assert np.all(w[centre & (p[:, 1] < -3.4) & (p[:, 1] > -5.0)] == 1.0)  # lower lip


@given(
    theta=st.tuples(st.floats(-0.6, 0.6), st.floats(-0.3, 0.3), st.floats(-1.0, 1.0)),
    seed=st.integers(0, 2**16),
)
@settings(max_examples=50, deadline=None)
def test_skin_jaw_with_full_weight_is_rigid(theta: tuple[float, float, float], seed: int) -> None:
    pts = np.random.default_rng(seed).normal(0.0, 5.0, (6, 3))
    th = np.array(theta)
    rig = JawRig(np.array([0.0, -1.5, 3.0]), np.ones(6))
    out = rig.skin(pts, th)
    d_in = np.linalg.norm(pts[:, None] - pts[None], axis=2)
    d_out = np.linalg.norm(out[:, None] - out[None], axis=2)
    np.testing.assert_allclose(d_out, d_in, atol=1e-9)
    r, _ = rig.transform(th)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    np.testing.assert_array_equal(JawRig(np.zeros(3), np.ones(6)).skin(pts, np.zeros(3)), pts)


def test_left_and_right_shapes_mirror_each_other(sample: Sample) -> None:
    mirror = mirror_index(sample.neutral)
    flip = np.array([-1.0, 1.0, 1.0])
    pairs = [(n, n[:-4] + "Right") for n in sample.names if n.endswith("Left")]
    assert len(pairs) >= 15
    for left, right in pairs:
        a = sample.shapes[sample.names.index(left)]
        b = sample.shapes[sample.names.index(right)]
        np.testing.assert_allclose(b[mirror] * flip, a, atol=1e-5, err_msg=left)


def second_to_first_difference(values: F64) -> float:
    """RMS of second differences over RMS of first differences along axis 0."""
    d1 = np.diff(values, axis=0)
    d2 = np.diff(values, 2, axis=0)
    return float(np.sqrt(np.mean(d2**2)) / np.sqrt(np.mean(d1**2)))


def test_brow_raise_has_forehead_wrinkles_the_neutral_lacks(sample: Sample) -> None:
    p = sample.neutral
    for name, x0 in (("browInnerUp", 0.0), ("browOuterUpLeft", 3.0)):
        xs = np.unique(p[:, 0])
        col = np.abs(p[:, 0] - xs[np.argmin(np.abs(xs - x0))]) < 1e-9
        col &= (p[:, 1] > 5.2) & (p[:, 1] < 7.2)
        order = np.argsort(p[col, 1])
        k = sample.names.index(name)
        shape_z = sample.shapes[k, col, 2][order].astype(np.float64)
        smooth = (sample.shapes[k, col] - sample.wrinkles[k, col])[order].astype(np.float64)
        assert second_to_first_difference(shape_z) > 0.5, name
        assert np.ptp(shape_z) > 0.1  # furrows of about a millimetre
        assert second_to_first_difference(smooth) < 0.2, name  # the lift alone is smooth
        assert second_to_first_difference(p[col, 2][order]) < 0.1


def test_expression_folds_are_high_frequency(sample: Sample) -> None:
    """Umbrella Laplacian (interior vertices) of each fold field is large relative to its edge
    differences, unlike the smooth part of the same shape and unlike the neutral."""
    tri = sample.triangles
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    edges, count = np.unique(edges, axis=0, return_counts=True)
    boundary = np.zeros(sample.num_vertices, dtype=bool)
    boundary[edges[count == 1].ravel()] = True
    deg = np.bincount(edges.ravel(), minlength=sample.num_vertices).astype(np.float64)

    def roughness(f: F64) -> float:
        nb = np.zeros_like(f)
        np.add.at(nb, edges[:, 0], f[edges[:, 1]])
        np.add.at(nb, edges[:, 1], f[edges[:, 0]])
        lap = (nb / deg[:, None] - f)[~boundary]
        return float(np.linalg.norm(lap) / np.linalg.norm(f[edges[:, 0]] - f[edges[:, 1]]))

    neutral = roughness(sample.neutral)
    with_folds = [k for k in range(sample.num_shapes) if np.any(sample.wrinkles[k] != 0)]
    assert len(with_folds) >= 20
    assert "mouthSmileLeft" in [sample.names[k] for k in with_folds]
    for k in with_folds:
        fold = sample.wrinkles[k].astype(np.float64)
        smooth = sample.shapes[k].astype(np.float64) - fold
        assert np.abs(fold).max() > 0.025, sample.names[k]  # at least 0.25 mm deep
        r = roughness(fold)
        assert r > 2.0 * roughness(smooth) and r > 5.0 * neutral, sample.names[k]


# ------------------------------------------------------------------------------------------
# Performance.


def test_truth_follows_the_documented_nonlinear_formula(sample: Sample) -> None:
    jaw_open = sample.names.index("jawOpen")
    frames = [0, int(np.argmax(sample.truth_weights[:, jaw_open])), sample.num_frames // 3]
    frames.append(int(np.argmax((sample.truth_weights > 0).sum(axis=1))))
    for f in frames:
        np.testing.assert_allclose(sample.truth[f], reference_truth(sample, f), atol=1e-9)


def test_truth_is_not_in_the_linear_span_of_the_shapes(sample: Sample) -> None:
    w = sample.truth_weights
    k = sample.names.index("jawOpen")
    half = np.nonzero(np.logical_and(w[:, k] > 0.3, w[:, k] < 0.8))[0]
    assert half.size > 0
    f = int(half[0])
    linear = sample.neutral + np.einsum("s,svd->vd", w[f], sample.shapes.astype(np.float64))
    assert np.abs(sample.truth[f] - linear).max() > 0.1  # a rotation is not a blend


def test_rest_frames_equal_the_neutral(sample: Sample) -> None:
    rest = np.nonzero(~sample.truth_weights.any(axis=1))[0]
    assert 0 in rest
    for f in rest:
        np.testing.assert_array_equal(sample.truth[f], sample.neutral)
        np.testing.assert_array_equal(sample.jaw_theta[f], 0.0)


def test_performance_is_truth_at_markers_plus_noise(sample: Sample) -> None:
    corners = sample.truth[:, sample.triangles[sample.marker_triangles]]  # (F, B, 3, 3)
    clean = np.einsum("bc,fbcd->fbd", sample.marker_barycentrics, corners)
    np.testing.assert_allclose(clean[0], sample.markers_rest, atol=1e-12)
    ok = ~np.isnan(sample.performance).any(axis=2)
    residual = (sample.performance - clean)[ok]
    assert residual.std() == pytest.approx(0.02, rel=0.1)  # 0.2 mm = 0.02 cm
    assert abs(residual.mean()) < 2e-3


def test_dropouts_are_nan_rows_in_short_runs(sample: Sample) -> None:
    nan = np.isnan(sample.performance)
    lost: NDArray[np.bool_] = np.asarray(nan.any(axis=2))
    np.testing.assert_array_equal(nan.all(axis=2), lost)  # whole (x, y, z) rows
    assert 0.01 <= lost.mean() <= 0.03
    assert not lost[0].any()
    starts = lost[1:] & ~lost[:-1]
    mean_run = lost.sum() / max(int(starts.sum()), 1)
    assert 2.0 <= mean_run <= 10.0


def test_weights_are_sparse_smooth_and_open_the_jaw_25_degrees(sample: Sample) -> None:
    w = sample.truth_weights
    assert w.min() >= 0.0 and w.max() <= 1.0
    assert 1.0 < (w > 0.05).sum(axis=1).mean() < 8.0
    assert np.abs(np.diff(w, 2, axis=0)).max() < 0.15  # a step would give about 1
    assert np.rad2deg(sample.jaw_theta[:, 0].max()) == pytest.approx(25.0, abs=0.1)


# ------------------------------------------------------------------------------------------
# Files, summary, arguments.


def test_save_and_load_round_trip(small: Sample, tmp_path: Path) -> None:
    path = tmp_path / "sample.npz"
    save_sample(small, path)
    back = load_sample(path)
    for name in (
        "neutral",
        "triangles",
        "uvs",
        "shapes",
        "wrinkles",
        "performance",
        "truth",
        "truth_weights",
        "jaw_theta",
        "jaw_pivot",
        "jaw_weights",
        "shape_jaw_theta",
        "markers_rest",
        "marker_triangles",
        "marker_barycentrics",
        "uv_triangles",
    ):
        a, b = getattr(small, name), getattr(back, name)
        assert a.dtype == b.dtype, name
        np.testing.assert_array_equal(a, b, err_msg=name)
    assert back.names == small.names and back.marker_names == small.marker_names
    assert back.seed == small.seed


def test_load_rejects_missing_and_foreign_files(tmp_path: Path) -> None:
    with pytest.raises(DatasetFileError):
        load_sample(tmp_path / "nope.npz")
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, a=np.zeros(3))
    with pytest.raises(DatasetError, match="missing"):
        load_sample(foreign)
    text = tmp_path / "text.npz"
    text.write_text("not a zip")
    with pytest.raises(DatasetError):
        load_sample(text)


def test_describe_reports_counts_and_size(small: Sample) -> None:
    text = describe(small)
    assert str(small.num_vertices) in text and str(small.num_shapes) in text
    assert str(small.num_markers) in text and str(small.num_frames) in text
    assert "cm" in text and "dropouts" in text and len(text.splitlines()) >= 7


@pytest.mark.parametrize(
    "kwargs",
    [
        {"resolution": 10},
        {"num_frames": 0},
        {"noise_mm": -1.0},
        {"dropout": 0.7},
        {"noise_mm": float("nan")},
    ],
)
def test_make_sample_rejects_bad_arguments(kwargs: dict[str, float]) -> None:
    with pytest.raises(InputError):
        make_sample(**kwargs)  # type: ignore[arg-type]
