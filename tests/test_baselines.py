"""Baselines against independent references: scipy's RBFInterpolator, brute-force enumeration
of the blendshape fit's active sets and scipy's L-BFGS-B; exact marker interpolation."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import lgi
from lgi import _lgi
from lgi.lab.baselines import BlendshapeFit, DisplacementInterpolation, LgiRbf


def test_rbf_kernel_matches_scipy_linear_rbf_with_linear_polynomial() -> None:
    from scipy.interpolate import RBFInterpolator

    rng = np.random.default_rng(0)
    pts = rng.uniform(-1, 1, (200, 3))
    centres = rng.choice(200, 25, replace=False)
    vals = rng.normal(size=(25, 3))
    sv = np.repeat(centres[:, None], 3, axis=1)
    sw = np.tile([1.0, 0.0, 0.0], (25, 1))
    rbf = _lgi.RbfInterpolator(pts, sv, sw)
    got = rbf.interpolate(vals[None])[0]
    want = RBFInterpolator(pts[centres], vals, kernel="linear", degree=1)(pts)
    assert np.abs(got - want).max() < 1e-8
    np.testing.assert_allclose(rbf.matrix @ vals, got, atol=1e-10)
    # Missing markers: the refit equals scipy's fit on the remaining ones.
    holes = vals.copy()
    holes[[2, 7]] = np.nan
    keep = np.setdiff1d(np.arange(25), [2, 7])
    got = rbf.interpolate(holes[None])[0]
    want = RBFInterpolator(pts[centres[keep]], vals[keep], kernel="linear", degree=1)(pts)
    assert np.abs(got - want).max() < 1e-8


def test_displacement_interpolation_passes_through_every_marker(sample, sample_dataset) -> None:  # type: ignore[no-untyped-def]
    m = DisplacementInterpolation(sample_dataset, sample.markers_rest)
    res = m.solve(sample.performance)
    diag = np.linalg.norm(np.ptp(sample.neutral, axis=0))
    assert res.bundle_residuals.max() <= 1e-9 * diag
    assert res.missing.sum() == np.isnan(sample.performance).any(axis=2).sum()
    assert (res.choices.shapes == -1).all() and (res.choices.weights == 0).all()
    assert res.vertices.shape == sample.truth.shape


def test_lgi_rbf_passes_through_every_marker_and_reports_lgi_choices(
    sample,  # type: ignore[no-untyped-def]
    sample_dataset,  # type: ignore[no-untyped-def]
) -> None:
    m = LgiRbf(sample_dataset, sample.markers_rest)
    frames = sample.performance[:20]
    res = m.solve(frames, quiet=True)
    diag = np.linalg.norm(np.ptp(sample.neutral, axis=0))
    assert res.bundle_residuals.max() <= 1e-9 * diag
    assert m.sigma > 0
    lgi_res = m.model.solve(frames, quiet=True)
    np.testing.assert_array_equal(res.choices.shapes, lgi_res.choices.shapes)


def _enumerate_active_sets(a, t, l2, p):  # type: ignore[no-untyped-def]
    """Exact reference: minimise each quadratic piece (each weight below 0, in [0,1] or above 1)
    and keep the consistent one with the lowest objective."""
    s = a.shape[1]
    best, best_f = None, np.inf
    for sides in itertools.product((-1, 0, 1), repeat=s):
        d = np.array([1.0 if x else 0.0 for x in sides])
        h = a.T @ a + l2 * np.eye(s) + p * np.diag(d)
        rhs = a.T @ t + p * (np.array(sides) == 1)
        w = np.linalg.solve(h, rhs)
        ok = all(
            (x < 0) if sd == -1 else (x > 1) if sd == 1 else (0 <= x <= 1)
            for x, sd in zip(w, sides, strict=True)
        )
        if ok:
            f = _objective(a, t, l2, p, w)
            if f < best_f:
                best, best_f = w, f
    return best, best_f


def _objective(a, t, l2, p, w):  # type: ignore[no-untyped-def]
    out = np.minimum(w, 0) + np.maximum(w - 1, 0)
    return float(np.sum((a @ w - t) ** 2) + l2 * w @ w + p * out @ out)


@pytest.mark.parametrize("seed", range(6))
def test_blendshape_solver_matches_exact_enumeration_and_lbfgsb(seed: int) -> None:
    from scipy.optimize import minimize

    rng = np.random.default_rng(seed)
    a = rng.normal(size=(18, 5))
    t = a @ rng.uniform(-0.8, 1.8, 5) + 0.1 * rng.normal(size=18)
    l2, p = 1e-3, 3.0
    solver = _lgi.BlendshapeSolver(a, l2, p)
    w, it = solver.solve(t[None])
    w = w[0]
    want, want_f = _enumerate_active_sets(a, t, l2, p)
    np.testing.assert_allclose(w, want, atol=1e-9)
    assert abs(solver.objective(w, t) - want_f) <= 1e-12 * max(want_f, 1.0)
    assert it[0] <= 20

    def f(x):  # type: ignore[no-untyped-def]
        out = np.minimum(x, 0) + np.maximum(x - 1, 0)
        g = 2 * a.T @ (a @ x - t) + 2 * l2 * x + 2 * p * out
        return _objective(a, t, l2, p, x), g

    ref = minimize(
        f,
        np.zeros(5),
        jac=True,
        method="L-BFGS-B",
        tol=1e-15,
        options={"maxiter": 10_000, "ftol": 1e-16, "gtol": 1e-12},
    )
    assert solver.objective(w, t) <= ref.fun * (1 + 1e-9)
    assert abs(ref.fun - want_f) <= 1e-9 * want_f
    np.testing.assert_allclose(w, ref.x, atol=1e-6)


def test_blendshape_missing_rows_equal_a_fit_without_them() -> None:
    rng = np.random.default_rng(7)
    a = rng.normal(size=(12, 4))
    t = rng.normal(size=12)
    solver = _lgi.BlendshapeSolver(a, 1e-3, 2.0)
    holes = t.copy()
    holes[[1, 5]] = np.nan
    keep = np.setdiff1d(np.arange(12), [1, 5])
    got = solver.solve(holes[None])[0][0]
    want = _lgi.BlendshapeSolver(a[keep], 1e-3, 2.0).solve(t[keep][None])[0][0]
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_blendshape_penalty_keeps_weights_near_the_unit_box(sample, sample_dataset) -> None:  # type: ignore[no-untyped-def]
    frames = sample.performance[:40] * 1.0
    frames = sample.markers_rest + 3.0 * (frames - sample.markers_rest)  # exaggerated motion
    loose = BlendshapeFit(sample_dataset, sample.markers_rest, penalty=0.0).weights(frames)
    tight = BlendshapeFit(sample_dataset, sample.markers_rest, penalty=1e4).weights(frames)

    def outside(w):  # type: ignore[no-untyped-def]
        return float(np.max(np.maximum(-w, 0) + np.maximum(w - 1, 0)))

    assert outside(loose) > 0.2
    assert outside(tight) < 0.02
    res = BlendshapeFit(sample_dataset, sample.markers_rest).solve(sample.performance[:5])
    assert res.vertices.shape == (5, *sample.neutral.shape)
    assert (res.choices.shapes == -1).all()


def test_bad_inputs_raise_input_error(sample, sample_dataset) -> None:  # type: ignore[no-untyped-def]
    m = DisplacementInterpolation(sample_dataset, sample.markers_rest)
    with pytest.raises(lgi.InputError):
        m.solve(np.zeros((2, 3, 3)))
    bad = sample.performance[:2].copy()
    bad[0, 0, 0] = np.inf
    with pytest.raises(lgi.InputError):
        m.solve(bad)
    with pytest.raises(lgi.InputError):
        DisplacementInterpolation(sample_dataset, np.zeros((5, 3), dtype=np.int64))
    with pytest.raises(lgi.InputError):
        BlendshapeFit(sample_dataset, sample.markers_rest, l2=-1.0)
    with pytest.raises(lgi.InputError):
        _lgi.BlendshapeSolver(np.zeros((4, 2)), 0.0, 0.0)  # singular normal matrix
    flat = np.c_[np.random.default_rng(0).uniform(size=(10, 2)), np.zeros(10)]
    with pytest.raises(lgi.InputError):
        _lgi.RbfInterpolator(flat, np.repeat(np.arange(6)[:, None], 3, 1), np.eye(6, 3))
    few = sample.performance[:1].copy()
    few[0, 3:] = np.nan
    with pytest.raises(lgi.InputError):
        m.solve(few)  # fewer than 4 markers present


def test_ict_displacement_interpolation_is_exact_and_blendshape_fit_explains_shapes(
    ict_dataset,  # type: ignore[no-untyped-def]
    ict_markers,  # type: ignore[no-untyped-def]
) -> None:
    from lgi.lab.scoring import verification

    frames, _truth = verification(ict_dataset, ict_markers)
    diag = np.linalg.norm(np.ptp(np.asarray(ict_dataset.neutral), axis=0))
    di = DisplacementInterpolation(ict_dataset, ict_markers).solve(frames[:4])
    assert di.bundle_residuals.max() <= 1e-9 * diag
    # Frames that are dataset shapes are (nearly) in the span: markers fit to 1e-3 diagonal.
    fit = BlendshapeFit(ict_dataset, ict_markers).solve(frames)
    assert fit.bundle_residuals.max() <= 1e-3 * diag


def test_fit_jaw_recovers_frames_made_by_its_own_rig_where_a_box_fit_cannot() -> None:
    from lgi.lab.baselines import BlendshapeFit, FitJaw
    from lgi.lab.sample import make_sample, sample_dataset

    s = make_sample(0)
    data = sample_dataset(s)
    model = lgi.Model.build(data, s.markers_rest)
    peer = FitJaw(model)
    # Frames of the peer's own form: jaw-unskinned shapes blended inside the box, skinned by
    # an opening of up to 0.3 rad (the unskinned shapes made independently of the peer).
    rig, theta_s = model.jaw_rig, model.core.jaw()["shape_theta"]
    x0, shapes = np.asarray(data.neutral), np.asarray(data.shapes)
    unskinned = np.stack(
        [rig.unskin_displacements(x0, shapes[k], theta_s[k]) for k in range(len(shapes))]
    )
    rng = np.random.default_rng(3)
    w = rng.uniform(0, 1, (8, data.num_shapes)) * (rng.random((8, data.num_shapes)) < 0.15)
    theta = np.zeros((8, 3))
    theta[:, 0] = rng.uniform(0.0, 0.3, 8)
    truth = rig.skin(x0[None] + np.einsum("fk,kvd->fvd", w, unskinned), theta)
    frames = model.bundle_positions(truth)
    got = peer.solve(frames)
    err = np.linalg.norm(got.vertices - truth, axis=2).mean()
    # The fit's ridge and box penalty leave a little (measured 3.9e-5 on a 23-unit face).
    assert err < 1e-5 * model.diagonal, err
    box = np.linalg.norm(BlendshapeFit(data, s.markers_rest).solve(frames).vertices - truth, axis=2)
    assert box.mean() > 100 * err  # the jaw's rotation is what a linear fit misses
    assert got.vertices.shape == truth.shape and not got.missing.any()
    with pytest.raises(lgi.InputError, match="needs a model built with a jaw rig"):
        FitJaw(lgi.Model.build(data, s.markers_rest, jaw=None))


def test_fit_jaw_unbounded_recovers_weights_outside_the_box_where_fit_jaw_cannot(
    outside_the_box,  # type: ignore[no-untyped-def]
) -> None:
    from lgi.lab.baselines import FitJaw, FitJawUnbounded, FitJawUnboundedResidual

    # Weights in [-1, 2] on the shapes that do not turn the jaw, at the rest pose.
    model, frames, truth = outside_the_box
    free = FitJawUnbounded(model).solve(frames)
    boxed = FitJaw(model).solve(frames)
    err_free = np.linalg.norm(free.vertices - truth, axis=2).mean()
    err_box = np.linalg.norm(boxed.vertices - truth, axis=2).mean()
    assert err_free < 0.1 * err_box, (err_free, err_box)
    # Its corrective takes most of what is left at the markers (measured 7.8e-4 -> 3.3e-5).
    corrected = FitJawUnboundedResidual(FitJawUnbounded(model), smoothing=[0.0]).solve(frames)
    assert corrected.bundle_residuals.mean() < 0.2 * free.bundle_residuals.mean()


def test_fit_jaw_residual_left_out_errors_equal_refits_without_each_marker() -> None:
    from lgi.lab.baselines import FitJaw, FitJawResidual
    from lgi.lab.sample import make_sample, sample_dataset

    s = make_sample(0)
    model = lgi.Model.build(sample_dataset(s), s.markers_rest)
    frames = np.asarray(s.performance[:12])
    jaw_peer = FitJaw(model)
    peer = FitJawResidual(jaw_peer)
    base = jaw_peer.solve(frames)
    r = (frames - base.bundle_positions)[3]
    lam = peer._candidates[3]
    # Brute force: the spline refitted without marker i, evaluated at marker i.
    present = np.isfinite(r).all(axis=1)
    brute = 0.0
    for i in np.flatnonzero(present):
        keep = present.copy()
        keep[i] = False
        n = int(keep.sum())
        coef = np.linalg.solve(peer._system(keep, lam), np.vstack([r[keep], np.zeros((4, 3))]))
        pred = peer._kbb[i, keep] @ coef[:n] + peer._pb[i] @ coef[n:]
        brute += float(np.sum((r[i] - pred) ** 2))
    assert peer.left_out_error(r[None], lam) == pytest.approx(brute, rel=1e-9)
    # The corrective takes most of the peer's marker residual (measured 0.0302 -> 0.0026).
    got = FitJawResidual(jaw_peer, smoothing=[0.0]).solve(frames)
    assert got.bundle_residuals.mean() < 0.2 * base.bundle_residuals.mean()
    with pytest.raises(lgi.InputError, match="smoothing"):
        FitJawResidual(jaw_peer, smoothing=[-1.0])


def test_ridge_weights_are_the_normal_equations_solution_with_more_columns_than_rows() -> None:
    from scipy.linalg import lstsq

    from lgi.lab.baselines import ridge_weights

    rng = np.random.default_rng(8)
    for rows, cols in ((30, 7), (12, 40)):
        a, b = rng.normal(size=(rows, cols)), rng.normal(size=rows)
        # Reference: the ridge as least squares on [a; sqrt(ridge) I] against [b; 0].
        stacked = np.vstack([a, np.sqrt(0.3) * np.eye(cols)])
        want = lstsq(stacked, np.concatenate([b, np.zeros(cols)]))[0]
        np.testing.assert_allclose(ridge_weights(a, b, 0.3), want, rtol=1e-10, atol=1e-12)
