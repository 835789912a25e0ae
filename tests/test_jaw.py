"""Jaw rig tooling (lgi.solve.jaw): the core's skinning against the numpy oracle, exact unskinning,
the core's pose fit (`JawRig.fit_pose`), rig and theta estimation from synthetic and sample
shapes, the model's tracked pose on the sample performance, and the ICT-FaceKit jaw (skipped
when the shared data is absent)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaw_oracle import jaw_transform, skin_jaw, unskin_jaw
from lgi import _lgi
from lgi.errors import InputError
from lgi.lab.ict import ENV as ICT_ENV
from lgi.lab.ict import LOWER_TEETH
from lgi.lab.ict import find as find_ict
from lgi.lab.sample import make_sample
from lgi.solve import jaw

PIVOT = np.array([0.3, -1.2, 2.5])


def _rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    a = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def _synthetic(seed: int = 3, frame: np.ndarray | None = None):
    """A blob of points: 150 rigidly on the jaw (w = 1), 150 partial, 100 on the skull."""
    rng = np.random.default_rng(seed)
    x0 = rng.uniform([-5, -8, 5], [5, 2, 10], size=(400, 3))
    w = np.concatenate([np.ones(150), rng.uniform(0.05, 0.95, 150), np.zeros(100)])
    rig = jaw.JawRig(PIVOT, w, np.eye(3) if frame is None else frame)
    thetas = {
        "jawOpen": [0.41, 0.0, 0.0],
        "jawLeft": [0.0, 0.11, 0.0],
        "jawRight": [0.0, -0.11, 0.0],
        "jawForward": [0.0, 0.0, 0.55],
        "mixed": [0.2, -0.07, 0.3],
    }
    names = [*thetas, "browUp"]
    shapes = [rig.skin(x0, th) - x0 for th in thetas.values()]
    brow = np.zeros_like(x0)
    brow[300:, 1] = rng.uniform(0.1, 0.3, 100)  # moves skull vertices only
    shapes.append(brow)
    truth = np.array([*thetas.values(), [0.0, 0.0, 0.0]])
    return rig, x0, np.stack(shapes), names, truth


def _deg(x: np.ndarray) -> np.ndarray:
    return np.rad2deg(x)


# --------------------------------------------------------------------------------------------
# Skinning.


def test_identity_frame_skin_matches_the_sample_generator_bit_for_bit() -> None:
    # The numpy oracle is the sample generator's former formula; the core sums each row with
    # fused multiply-adds in the order numpy's matrix product (OpenBLAS) takes, so they agree
    # to the bit and the sample is unchanged.
    rng = np.random.default_rng(0)
    p = rng.normal(size=(200, 3)) * 4
    w = rng.uniform(0, 1, 200)
    rig = jaw.JawRig(PIVOT, w)
    for th in ([0.4, 0.1, 0.3], [-0.2, -0.25, -1.0], [0.0, 0.0, 0.0]):
        np.testing.assert_array_equal(rig.skin(p, th), skin_jaw(p, np.array(th), PIVOT, w))
        r, t = rig.transform(th)
        r_ref, t_ref = jaw_transform(np.array(th))
        np.testing.assert_array_equal(r, r_ref)
        np.testing.assert_array_equal(t, t_ref)


def test_frames_of_points_skin_each_with_its_own_pose_like_one_call_per_frame() -> None:
    rng = np.random.default_rng(4)
    frames = rng.normal(size=(5, 30, 3)) * 4
    thetas = rng.uniform(-0.4, 0.4, size=(5, 3))
    w = rng.uniform(0, 1, 30)
    rig = jaw.JawRig(PIVOT, w, _rodrigues([1, 0.5, 0], 0.2))
    skinned = rig.skin(frames, thetas)
    assert skinned.shape == frames.shape
    for f in range(5):
        np.testing.assert_array_equal(skinned[f], rig.skin(frames[f], thetas[f]))
        np.testing.assert_array_equal(
            rig.unskin(skinned, thetas)[f], rig.unskin(skinned[f], thetas[f])
        )
    one_pose = rig.skin(frames, thetas[0], np.ones(30))
    np.testing.assert_array_equal(one_pose[3], rig.skin(frames[3], thetas[0], np.ones(30)))


def test_weight_one_points_follow_the_closed_form_rotation_about_the_pivot() -> None:
    rng = np.random.default_rng(1)
    p = rng.normal(size=(50, 3)) * 5
    rig = jaw.JawRig(PIVOT, np.ones(50))
    th = np.array([0.35, -0.12, 0.4])
    r = _rodrigues([0, 1, 0], th[1]) @ _rodrigues([1, 0, 0], th[0])
    expected = (p - PIVOT) @ r.T + PIVOT + [0, 0, th[2]]
    np.testing.assert_allclose(rig.skin(p, th), expected, atol=1e-12)


def test_weight_zero_points_and_the_rest_pose_are_untouched() -> None:
    p = np.array([[1.0, -5.0, 8.0], [0.5, -6.0, 9.0]])
    rig = jaw.JawRig(PIVOT, np.array([0.0, 0.6]))
    out = rig.skin(p, [0.4, 0.1, 0.2])
    np.testing.assert_array_equal(out[0], p[0])
    np.testing.assert_array_equal(rig.skin(p, [0, 0, 0]), p)
    np.testing.assert_array_equal(rig.unskin(p, [0, 0, 0]), p)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(
    open_deg=st.floats(-40, 40),
    lateral_deg=st.floats(-15, 15),
    forward=st.floats(-2, 2),
    w=st.floats(0, 1),
    seed=st.integers(0, 2**16),
)
def test_unskin_inverts_skin_to_1e12_relative(
    open_deg: float, lateral_deg: float, forward: float, w: float, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    p = rng.uniform(-10, 10, size=(20, 3))
    frame = _rodrigues(rng.normal(size=3), rng.uniform(0, 0.3))
    rig = jaw.JawRig(PIVOT, np.full(20, w), frame)
    th = [np.deg2rad(open_deg), np.deg2rad(lateral_deg), forward]
    scale = 1 + np.linalg.norm(p, axis=1).max() + np.linalg.norm(PIVOT)
    assert np.abs(rig.unskin(rig.skin(p, th), th) - p).max() <= 1e-12 * scale
    assert np.abs(rig.skin(rig.unskin(p, th), th) - p).max() <= 1e-12 * scale


def test_rig_round_trips_through_npz(tmp_path: Path) -> None:
    rig = jaw.JawRig(PIVOT, np.linspace(0, 1, 7), _rodrigues([1, 2, 3], 0.2))
    np.savez(tmp_path / "rig.npz", **rig.to_dict())
    with np.load(tmp_path / "rig.npz") as z:
        back = jaw.JawRig.from_dict(z)
    np.testing.assert_array_equal(back.pivot, rig.pivot)
    np.testing.assert_array_equal(back.weights, rig.weights)
    np.testing.assert_array_equal(back.frame, rig.frame)


def test_the_rig_is_the_cores_class_with_the_tooling() -> None:
    assert jaw.JawRig is _lgi.JawRig
    assert not hasattr(jaw.JawRig, "of")
    with pytest.raises(TypeError):
        type("Sub", (jaw.JawRig,), {})  # final: one JawRig


def test_unskin_displacements_is_the_unskinned_shape_minus_the_neutral() -> None:
    rig, x0, shapes, _, truth = _synthetic(frame=_rodrigues([1, 2, 0.5], 0.3))
    for s, th in zip(shapes, truth, strict=True):
        star = rig.unskin_displacements(x0, s, th)
        np.testing.assert_array_equal(star, rig.unskin(x0 + s, th) - x0)
        oracle = unskin_jaw(x0 + s, th, rig.pivot, rig.weights, rig.frame) - x0
        np.testing.assert_allclose(star, oracle, atol=1e-12 * (1 + np.abs(x0).max()))
    # The synthetic jaw shapes are pure jaw motion: unskinned, nothing is left.
    assert np.abs(rig.unskin_displacements(x0, shapes[0], truth[0])).max() < 1e-12


def test_bundle_weights_are_the_barycentric_blend_clipped_bit_for_bit() -> None:
    rng = np.random.default_rng(7)
    v, t, b = 60, 80, 50
    tris = rng.integers(0, v, size=(t, 3))
    w = rng.uniform(0, 1, v)
    bt = rng.integers(0, t, size=b)
    bc = rng.dirichlet(np.ones(3), size=b)
    w[tris[bt[:5]]] = 1.0
    bc[:5] *= 1.5  # outside the triangle: above 1, clipped
    bc[5:8] *= -1.0  # below 0, clipped
    rig = jaw.JawRig(PIVOT, w)
    corner = w[tris[bt]]
    # The sum in corner order, as the core (and so a model's bundles) adds it.
    expected = np.clip(
        bc[:, 0] * corner[:, 0] + bc[:, 1] * corner[:, 1] + bc[:, 2] * corner[:, 2], 0.0, 1.0
    )
    got = rig.bundle_weights(tris, bt, bc)
    assert got.dtype == np.float64 and got.shape == (b,)
    np.testing.assert_array_equal(got, expected)
    # einsum (the former Python formula) sums in its own order: the same to an ulp.
    einsum = np.clip(np.einsum("bc,bc->b", bc, corner), 0.0, 1.0)
    np.testing.assert_allclose(got, einsum, rtol=0, atol=4e-16)
    assert (got[:5] == 1.0).all() and (got[5:8] == 0.0).all()
    assert rig.bundle_weights(tris, np.zeros(0, np.int64), np.zeros((0, 3))).shape == (0,)


def test_rig_tooling_arguments_raise_input_error_naming_the_problem() -> None:
    rig = jaw.JawRig(PIVOT, np.ones(4))
    tris = np.array([[0, 1, 2], [1, 2, 3]])
    with pytest.raises(InputError, match=r"triangles must have shape \(T, 3\), got \(2, 2\)"):
        rig.bundle_weights(tris[:, :2], [0], [[1.0, 0, 0]])
    with pytest.raises(InputError, match=r"barycentrics must have shape \(1, 3\), got \(1, 2\)"):
        rig.bundle_weights(tris, [0], [[1.0, 0]])
    with pytest.raises(InputError, match="bundle triangle index out of range"):
        rig.bundle_weights(tris, [2], [[1.0, 0, 0]])
    with pytest.raises(InputError, match="bundle triangle index out of range"):
        rig.bundle_weights(tris, [-1], [[1.0, 0, 0]])
    with pytest.raises(InputError, match="out of range of the rig's weights"):
        rig.bundle_weights(np.array([[0, 1, 4]]), [0], [[1.0, 0, 0]])
    x0 = np.zeros((4, 3))
    with pytest.raises(InputError, match=r"neutral must have shape \(N, 3\), got \(4,\)"):
        rig.unskin_displacements(np.zeros(4), x0, [0, 0, 0])
    with pytest.raises(InputError, match=r"displacements \(3, 3\) do not match neutral \(4, 3\)"):
        rig.unskin_displacements(x0, x0[:3], [0, 0, 0])
    with pytest.raises(InputError, match="theta"):
        rig.unskin_displacements(x0, x0, [np.nan, 0, 0])
    with pytest.raises(InputError, match="jaw rig is missing jaw_pivot, jaw_weights"):
        jaw.JawRig.from_dict({})


def test_invalid_rigs_and_arguments_raise_input_error_naming_the_problem() -> None:
    with pytest.raises(InputError, match="vertex 2"):
        jaw.JawRig(PIVOT, np.array([0.0, 1.0, 1.5]))
    with pytest.raises(InputError, match="rotation"):
        jaw.JawRig(PIVOT, np.ones(2), np.diag([1.0, 1.0, -1.0]))
    rig = jaw.JawRig(PIVOT, np.ones(2))
    with pytest.raises(InputError, match="weights"):
        rig.skin(np.zeros((3, 3)), [0, 0, 0])
    with pytest.raises(InputError, match="theta"):
        rig.skin(np.zeros((2, 3)), [np.nan, 0, 0])
    with pytest.raises(InputError, match="missing"):
        jaw.JawRig.from_dict({"jaw_pivot": PIVOT})
    _, x0, shapes, names, _ = _synthetic()
    with pytest.raises(InputError, match="jawOpen"):
        jaw.estimate_rig(x0, shapes, [n.replace("jawOpen", "open") for n in names])


# --------------------------------------------------------------------------------------------
# Estimation.


def test_estimate_rig_recovers_known_theta_pivot_and_weights_from_synthetic_shapes() -> None:
    rig, x0, shapes, names, truth = _synthetic()
    est, theta, rep = jaw.estimate_rig(x0, shapes, names, return_report=True)
    err = np.abs(theta - truth).max()
    print(
        f"\nsynthetic: theta max error {err:.2e}, pivot error "
        f"{np.linalg.norm(est.pivot - PIVOT):.2e}, rigid set {rep.rigid_vertices.size}"
    )
    assert err <= 1e-6
    np.testing.assert_allclose(est.pivot, PIVOT, atol=1e-6)
    np.testing.assert_allclose(rep.open_axis, [1, 0, 0], atol=1e-9)
    np.testing.assert_allclose(est.weights, rig.weights, atol=1e-6)
    assert set(rep.rigid_vertices.tolist()) == set(range(150))


def test_estimate_rig_with_given_rigid_vertices_and_tilted_axes_recovers_the_frame() -> None:
    frame = _rodrigues([0.3, -0.5, 1.0], 0.15)
    _, x0, shapes, names, truth = _synthetic(seed=5, frame=frame)
    est, theta = jaw.estimate_rig(
        x0, shapes, names, rigid_vertices=np.arange(150), estimate_frame=True
    )
    np.testing.assert_allclose(est.frame, frame, atol=1e-9)
    np.testing.assert_allclose(est.pivot, PIVOT, atol=1e-6)
    assert np.abs(theta - truth).max() <= 1e-6


def test_fit_pose_recovers_theta_from_partially_weighted_points() -> None:
    for frame in (None, _rodrigues([0.3, -0.5, 1.0], 0.15)):
        rig, x0, *_ = _synthetic(frame=frame)
        th = np.array([0.3, 0.08, -0.4])
        target = rig.skin(x0, th)
        got = rig.fit_pose(x0[150:300], target[150:300], rig.weights[150:300])
        np.testing.assert_allclose(got, th, atol=1e-10)
        # From a start near the answer, robustly: the same pose.
        near = rig.fit_pose(
            x0[150:300], target[150:300], rig.weights[150:300], theta0=th + 0.01, huber=1.345
        )
        np.testing.assert_allclose(near, th, atol=1e-10)


def test_fit_pose_checks_its_arguments() -> None:
    rig, x0, *_ = _synthetic()
    with pytest.raises(InputError, match="targets"):
        rig.fit_pose(x0[:10], x0[:9])
    with pytest.raises(InputError, match="weights"):
        rig.fit_pose(x0[:10], x0[:10], np.ones(3))
    with pytest.raises(InputError, match="theta0"):
        rig.fit_pose(x0[:10], x0[:10], theta0=[4.0, 0.0, 0.0])
    with pytest.raises(InputError, match="points"):
        rig.fit_pose(x0[:10, :2], x0[:10, :2])


@pytest.fixture(scope="module")
def sample():
    return make_sample()


def test_estimate_rig_on_the_sample_matches_its_true_jaw(sample) -> None:
    s = sample
    est, theta, rep = jaw.estimate_rig(s.neutral, s.shapes, s.names, return_report=True)
    smoothed, _ = jaw.estimate_rig(s.neutral, s.shapes, s.names, triangles=s.triangles)
    pivot_err = np.linalg.norm(est.pivot - s.jaw_pivot)
    axis_err = np.degrees(np.arcsin(min(1.0, np.linalg.norm(rep.open_axis[1:]))))
    theta_err = np.abs(theta - s.shape_jaw_theta)
    w_err = np.abs(est.weights - s.jaw_weights).max()
    ws_err = np.abs(smoothed.weights - s.jaw_weights)
    print(
        f"\nsample rig: pivot error {pivot_err:.2e} cm, axis error {axis_err:.2e} deg, "
        f"open {np.degrees(rep.open_angle):.6f} deg, shape theta max error "
        f"{_deg(theta_err[:, :2]).max():.2e} deg / {theta_err[:, 2].max():.2e} cm, "
        f"weights max error {w_err:.2e} (smoothed: max {ws_err.max():.3f}, "
        f"mean {ws_err.mean():.1e})"
    )
    assert pivot_err < 1e-5
    assert axis_err < 1e-5
    assert _deg(theta_err[:, :2]).max() < 1e-5 and theta_err[:, 2].max() < 1e-5
    assert w_err < 1e-5
    assert ws_err.max() < 0.05
    # Expressions that pull the chin skin are not jaw motion.
    jaw_shapes = np.abs(s.shape_jaw_theta).max(axis=1) > 0
    assert np.all(theta[~jaw_shapes] == 0)
    assert np.all(rep.explained[jaw_shapes] > 0.999999)


def test_tracked_pose_follows_the_sample_performance(sample) -> None:
    # The tracking itself (exactness on pure jaw frames, gaps, the moving average) is tested
    # in the core (model/pose.rs); here the whole model on the sample's performance.
    import lgi
    from lgi.lab.sample import sample_dataset

    s = sample
    rig, theta = jaw.estimate_rig(s.neutral, s.shapes, s.names, triangles=s.triangles)
    model = lgi.Model.build(sample_dataset(s), s.markers_rest, jaw=rig, shape_theta=theta)
    res = model.solve(s.performance, jaw="track", quiet=True)
    assert res.jaw_theta is not None
    e = np.abs(res.jaw_theta - s.jaw_theta)
    bw = model.core.jaw()["bundle_weights"]  # type: ignore[index]
    print(
        f"\nsample tracking ({int((bw > 0.5).sum())} jaw bundles): "
        f"open mean {_deg(e[:, 0]).mean():.3f} max {_deg(e[:, 0]).max():.3f} deg, "
        f"lateral mean {_deg(e[:, 1]).mean():.3f} max {_deg(e[:, 1]).max():.3f} deg, "
        f"forward mean {e[:, 2].mean():.4f} max {e[:, 2].max():.4f} cm"
    )
    assert _deg(e[:, :2]).mean() < 0.5
    assert _deg(e[:, :2]).max() < 3.0
    assert e[:, 2].max() < 0.2


# --------------------------------------------------------------------------------------------
# ICT-FaceKit (real data, optional).


def _ict_root() -> Path | None:
    return find_ict(os.environ.get(ICT_ENV), start=Path(__file__).parent)


def _obj_vertices(path: Path) -> np.ndarray:
    with open(path) as f:
        coords = [line[2:] for line in f if line.startswith("v ")]
    return np.array(" ".join(coords).split(), dtype=np.float64).reshape(-1, 3)


@pytest.fixture(scope="module")
def ict():
    root = _ict_root()
    if root is None:
        pytest.skip("ICT-FaceKit data not found (set LGI_SHARED_DATA)")
    x0 = _obj_vertices(root / "generic_neutral_mesh.obj")
    names = sorted(p.stem for p in (root / "shapes").glob("*.obj"))
    shapes = np.stack([_obj_vertices(root / "shapes" / f"{n}.obj") - x0 for n in names])
    return x0, shapes, names


def test_ict_jaw_open_is_a_25_degree_hinge_near_the_documented_pivot(ict) -> None:
    x0, shapes, names = ict
    lo, hi = LOWER_TEETH
    rig, theta, rep = jaw.estimate_rig(
        x0, shapes, names, rigid_vertices=np.arange(lo, hi + 1), return_report=True
    )
    axis_dev = np.degrees(np.arcsin(min(1.0, np.linalg.norm(rep.open_axis[1:]))))
    lines = [
        f"\nICT: jawOpen {np.degrees(rep.open_angle):.3f} deg about {np.round(rep.open_axis, 6)} "
        f"(off x by {axis_dev:.2e} deg), pivot {np.round(rig.pivot, 4)}, teeth rigid-fit RMS "
        f"{rep.rigid_rms:.4f} cm"
    ]
    for n, th in rep.jaw_theta.items():
        k = names.index(n)
        lines.append(
            f"  {n}: open {np.degrees(th[0]):.3f} deg, lateral {np.degrees(th[1]):.3f} deg, "
            f"forward {th[2]:.4f} cm, explained {rep.explained[k]:.5f}"
        )
    moved = [
        n for n, th in zip(names, theta, strict=True) if np.any(th != 0) and n not in rep.jaw_theta
    ]
    lines.append(f"  other shapes with jaw motion: {moved}")
    lines.append(f"  vertices with weight > 0.5: {int((rig.weights > 0.5).sum())}")
    print("\n".join(lines))
    assert 23.0 < np.degrees(rep.open_angle) < 27.0
    assert axis_dev < 1.0
    assert abs(rig.pivot[0]) < 0.05
    assert abs(rig.pivot[1] + 0.55) < 0.1 and abs(rig.pivot[2] - 1.82) < 0.1
    assert rep.rigid_rms < 0.05
    assert theta[names.index("jawForward"), 2] > 0.5
    assert theta[names.index("jawLeft"), 1] > 0 > theta[names.index("jawRight"), 1]
    np.testing.assert_array_equal(rig.weights[lo : hi + 1], 1.0)
    np.testing.assert_array_equal(rig.weights[17039:19247], 0.0)  # upper teeth stay on the skull


def test_ict_every_shape_unskins_and_reskins_exactly(ict) -> None:
    x0, shapes, names = ict
    lo, hi = LOWER_TEETH
    rig, theta = jaw.estimate_rig(x0, shapes, names, rigid_vertices=np.arange(lo, hi + 1))
    diag = np.linalg.norm(x0.max(axis=0) - x0.min(axis=0))
    worst = 0.0
    for k in range(len(names)):
        star = rig.unskin_displacements(x0, shapes[k], theta[k])
        back = rig.skin(x0 + star, theta[k]) - x0
        worst = max(worst, float(np.abs(back - shapes[k]).max()))
    print(f"\nICT round trip unskin -> reskin: max error {worst / diag:.2e} of the diagonal")
    assert worst <= 1e-9 * diag
