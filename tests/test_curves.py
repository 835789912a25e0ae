"""Curves out of a solve: the global fit's weights as USD `UsdSkel` animation read back through
`UsdSkel` equal `fit_weights`, and pass every registered `pxr.UsdValidation` validator; a
Live Link Face CSV written from an ICT solve reads back through `read_livelinkface` with the
same curves, its columns in the order of the shared real recordings."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import lgi
from lgi.io.curves import ARKIT_CURVES, write_livelink_csv, write_usd_curves
from lgi.io.livelink import read_livelinkface
from pipeline_files import lgi_cli, write_actor, write_c3d


def validation_errors(path: Path) -> list[str]:
    """Every registered `pxr.UsdValidation` validator run on the stage at `path`."""
    from pxr import Usd, UsdValidation

    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    assert len(validators) > 10
    errors = UsdValidation.ValidationContext(validators).Validate(Usd.Stage.Open(str(path)))
    return [f"{e.GetName()}: {e.GetMessage()}" for e in errors]


def skel_weights(path: Path) -> tuple[list[str], np.ndarray, list[float]]:
    """(blend-shape names, (F, S) weights, time codes) read through `UsdSkel`'s binding."""
    from pxr import Usd, UsdSkel

    stage = Usd.Stage.Open(str(path))
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(stage.GetDefaultPrim())
    cache.Populate(root, Usd.PrimDefaultPredicate)
    bindings = cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
    query = cache.GetSkelQuery(bindings[0].GetSkeleton())
    anim = query.GetAnimQuery()
    names = [str(n) for n in anim.GetBlendShapeOrder()]
    attr = UsdSkel.Animation(anim.GetPrim()).GetBlendShapeWeightsAttr()
    times = attr.GetTimeSamples()
    w = np.array([np.array(anim.ComputeBlendShapeWeights(t)) for t in times])
    return names, w, times


@pytest.fixture(scope="module")
def ict_fit(ict_model, ict_path):  # type: ignore[no-untyped-def]
    """A 40-frame ICT capture from a shared Live Link recording, solved: (result, weights)."""
    from lgi.lab import ict
    from lgi.lab.capture import make_capture

    rec = ict.livelinkface(ict_path.parent)
    curves = read_livelinkface(rec[0])
    w = curves.for_dataset(ict_model.dataset.names)[200:240]
    frames = make_capture(
        ict_model.dataset,
        w,
        ict_model.markers_rest,
        sigma=0.0,
        dropout=0.0,
        holdout=0,
        seed=0,
        jaw=None,
    ).frames
    res = ict_model.solve(frames, marker_noise=0.05, quiet=True)  # the recommended path fits
    assert res.fit_weights is not None
    return res


def test_usd_curves_read_back_through_usdskel_equal_the_fit_and_validate(
    ict_model, ict_fit, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    out = write_usd_curves(
        tmp_path / "curves.usda",
        ict_model.dataset,
        ict_fit.fit_weights,
        fps=60.0,
        start=11,
        units="cm",
        jaw_theta=np.zeros((40, 3)),
    )
    names, w, times = skel_weights(out)
    assert names == list(ict_model.dataset.names)
    assert times == [float(t) for t in range(11, 51)]
    np.testing.assert_array_equal(w, ict_fit.fit_weights.astype(np.float32))
    assert validation_errors(out) == []


def test_a_live_link_csv_from_an_ict_solve_reads_back_with_the_same_curves(
    ict_model, ict_fit, ict_path, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    from lgi.lab import ict

    fit = ict_fit.fit_weights
    names = list(ict_model.dataset.names)
    with pytest.warns(lgi.LgiWarning, match="have no ARKit curve"):
        # From time code 100 (1.67 s): the frame field reaches 59, which is how the reader
        # tells 60 frames per second from 48 (a Live Link timecode does not carry its rate).
        out = write_livelink_csv(tmp_path / "take.csv", names, fit, fps=60.0, start=100)
    back = read_livelinkface(out)
    assert back.names == list(ARKIT_CURVES)
    # The column order of the real recordings' first 52 curves.
    assert back.names == read_livelinkface(ict.livelinkface(ict_path.parent)[0]).names[:52]
    np.testing.assert_allclose(back.times, np.arange(40) / 60.0, atol=1e-6)
    # Shapes one curve drives come back as the fit (to the CSV's 6 digits); two-sided shapes
    # under one curve (BrowInnerUp, CheekPuff) as their mean.
    again = back.for_dataset(names)
    single = [names.index(n) for n in ("jawOpen", "eyeBlink_L", "mouthSmile_R")]
    np.testing.assert_allclose(again[:, single], fit[:, single], rtol=1e-5, atol=1e-6)
    both = [names.index("browInnerUp_L"), names.index("browInnerUp_R")]
    np.testing.assert_allclose(again[:, both[0]], fit[:, both].mean(axis=1), atol=1e-5)


def test_lgi_solve_curves_writes_usd_curves_equal_to_model_solve(sample, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    actor = write_actor(tmp_path, sample, num_shapes=8)
    model = tmp_path / "m.lgi"
    p = lgi_cli("build", actor.neutral, actor.shapes, actor.markers, "-o", model, "--units", "cm")
    assert p.returncode == 0, p.stderr
    frames = np.asarray(sample.performance[:30])
    write_c3d(tmp_path / "take.c3d", frames, actor.names, 30.0, "cm")
    curves = tmp_path / "curves.usd"
    p = lgi_cli("solve", model, tmp_path / "take.c3d", "-o", tmp_path / "o.npz", "--curves", curves)
    assert p.returncode == 0, p.stderr
    m = lgi.Model.load(model)
    from lgi.io import takes

    # The same frames as the command read them (the C3D stores float32).
    read = takes.read(tmp_path / "take.c3d", m.marker_names, units=m.units).frames
    want = m.solve(read, quiet=True).fit_weights
    _, w, times = skel_weights(curves)
    assert times[0] == 1.0  # the C3D's first frame
    np.testing.assert_allclose(w, want, rtol=0, atol=1e-6)
    p = lgi_cli(
        "solve",
        model,
        tmp_path / "take.c3d",
        "-o",
        tmp_path / "o2.npz",
        "--curves",
        tmp_path / "c.fbx",
    )
    assert p.returncode == 2 and "--curves" in p.stderr and ".csv (Live Link Face)" in p.stderr


def test_every_usd_lgi_writes_passes_the_registered_validators(sample, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    from lgi.io.rig import write_usd_rig
    from lgi.io.topology import topology
    from lgi.io.usd import UsdCache
    from lgi.lab.sample import sample_dataset

    d = sample_dataset(sample)
    with UsdCache(tmp_path / "cache.usd", topology(d), fps=30.0, units="cm", start=1) as cache:
        cache.add(
            np.asarray(sample.truth[:5]),
            jaw_theta=np.zeros((5, 3)),
            marker_residuals=np.zeros((5, 4)),
            head_rotations=np.tile(np.eye(3), (5, 1, 1)),
            head_translations=np.zeros((5, 3)),
        )
    write_usd_rig(tmp_path / "rig.usda", d, units="cm")
    for name in ("cache.usd", "rig.usda"):
        assert validation_errors(tmp_path / name) == [], name
