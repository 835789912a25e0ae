"""Leave-one-marker-out on real takes (`lgi.lab.lomo`): the similarity and closest points against
closed forms and brute force, the retarget of a take made from the model recovering its layout
and motion exactly, the scoring chain giving zero for a method that is exact, and the protocol
on the shared AnimFace takes."""

from __future__ import annotations

import csv
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from conftest import ict_dir
from lgi.errors import InputError
from lgi.io.takes import RawTake
from lgi.lab import ict, lomo


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def test_similarity_recovers_a_known_scale_rotation_and_translation() -> None:
    rng = np.random.default_rng(1)
    src = rng.normal(size=(17, 3))
    rot, s, t = _rotation(rng), 0.87, np.array([3.0, -1.0, 40.0])
    got_s, got_r, got_t = lomo.similarity(src, s * src @ rot.T + t)
    assert got_s == pytest.approx(s, rel=1e-12)
    np.testing.assert_allclose(got_r, rot, atol=1e-12)
    np.testing.assert_allclose(got_t, t, atol=1e-11)


def test_similarity_of_a_mirrored_face_is_still_a_rotation() -> None:
    rng = np.random.default_rng(2)
    src = rng.normal(size=(10, 3))
    _, rot, _ = lomo.similarity(src, src * np.array([-1.0, 1.0, 1.0]))
    assert np.linalg.det(rot) == pytest.approx(1.0, abs=1e-12)


def _dense_distance(x: np.ndarray, tri: np.ndarray, n: int = 120) -> float:
    """Distance from x to a dense barycentric grid on each triangle (an independent reference)."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    u, v = i[keep] / n, j[keep] / n
    pts = (1 - u - v)[None, :, None] * tri[:, None, 0] + u[None, :, None] * tri[:, None, 1]
    pts = pts + v[None, :, None] * tri[:, None, 2]
    return float(np.linalg.norm(pts - x, axis=2).min())


@given(st.integers(0, 2**32 - 1))
def test_closest_surface_points_are_no_farther_than_a_dense_sampling_and_lie_on_the_triangle(
    seed: int,
) -> None:
    rng = np.random.default_rng(seed)
    verts = rng.normal(size=(9, 3))
    tris = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8], [0, 4, 8]])
    pts = rng.normal(scale=1.5, size=(4, 3))
    rows, bary, on = lomo.closest_surface_points(pts, verts, tris)
    assert np.all(bary >= -1e-12) and np.allclose(bary.sum(axis=1), 1.0)
    np.testing.assert_allclose(on, np.einsum("pk,pkd->pd", bary, verts[tris[rows]]), atol=1e-12)
    for x, p in zip(pts, on, strict=True):
        dense = _dense_distance(x, verts[tris])
        got = float(np.linalg.norm(p - x))
        assert got <= dense + 1e-12
        assert got >= dense - 0.05  # the grid's spacing bounds how much closer a point can be


def test_held_out_markers_start_with_the_most_moving_then_the_farthest_at_rest() -> None:
    rest = np.array([[0.0, 0, 0], [1, 0, 0], [5, 0, 0], [2, 0, 0], [9, 0, 0]])
    frames = np.repeat(rest[None], 3, axis=0)
    frames[:, 3, 1] += 0.7  # marker 3 moves most
    assert lomo.held_out_markers(rest, frames, [0, 1, 2, 3, 4], 3) == [3, 4, 2]
    assert lomo.held_out_markers(rest, frames, [0, 1, 2], 2) == [0, 2]  # none moves: first
    with pytest.raises(InputError, match=r"need 1\.\.3"):
        lomo.held_out_markers(rest, frames, [0, 1, 2], 4)


def _synthetic_take(dataset, landmarks):  # type: ignore[no-untyped-def]
    """A take made from the model itself: AnimFace's landmark markers on ICT's landmark
    vertices, the skull markers held at their rest (every ICT face vertex moves in some
    shape, so the skull's are placed, not blended), a few more on the face; frames blend the
    shapes with weights in [0, 1] and carry a different head pose each frame, all at a
    performer's scale."""
    rng = np.random.default_rng(5)
    shapes = np.asarray(dataset.shapes)
    neutral = np.asarray(dataset.neutral)
    face = ict.face_triangles(dataset)
    others = rng.choice(np.unique(face), 12, replace=False)
    free = np.setdiff1d(np.unique(face), [*landmarks, *others])
    skull = free[[0, free.size // 2, -1]]
    names = list(lomo.ANIMFACE_IBUG) + [n for n in lomo.RIGID if n != "NoseTop"]
    verts = [int(landmarks[k]) for k in lomo.ANIMFACE_IBUG.values()] + list(skull[:3])
    names += [f"extra{i}" for i in range(len(others))]
    verts += [int(v) for v in others]
    weights = rng.uniform(0, 0.6, size=(6, shapes.shape[0])) * (rng.random((6, 1)) > 0)
    weights[0] = 0.0  # the rest frame
    meshes = neutral[None] + np.einsum("fk,kvd->fvd", weights, shapes)
    held = [*skull[:3], int(landmarks[lomo.ANIMFACE_IBUG["NoseTop"]])]  # NoseTop is skull too
    meshes[:, held] = neutral[held]
    truth = meshes[:, verts]
    s = 1.14  # the performer is bigger than the model
    head = [_rotation(rng) for _ in range(6)]
    points = np.stack([(truth[f] / s) @ r.T + rng.normal(size=3) for f, r in enumerate(head)])
    take = RawTake(labels=names, points=points, fps=60.0, units="cm", path="synthetic.trc")
    return take, truth, np.array(verts), meshes


def test_retarget_of_a_take_made_from_the_model_recovers_its_layout_and_motion(
    ict_dataset,  # type: ignore[no-untyped-def]
) -> None:
    landmarks = ict.load_landmarks(ict_dir())
    take, truth, verts, _ = _synthetic_take(ict_dataset, landmarks)
    marks = {n: int(landmarks[k]) for n, k in lomo.ANIMFACE_IBUG.items()}
    got = lomo.retarget(take, ict_dataset.neutral, ict.face_triangles(ict_dataset), marks)
    assert got.scale == pytest.approx(1.14, rel=1e-9)
    assert got.landmark_residual < 1e-9
    np.testing.assert_allclose(got.rest, truth[0], atol=1e-9)
    np.testing.assert_allclose(got.frames, truth, atol=1e-8)
    # Each rest position is its own vertex: the barycentric sample reads that vertex back.
    on = np.einsum("bk,bkd->bd", got.barycentrics, np.asarray(ict_dataset.neutral)[got.corners])
    np.testing.assert_allclose(on, np.asarray(ict_dataset.neutral)[verts], atol=1e-9)


def test_lomo_scores_zero_for_the_true_meshes_and_the_motion_for_no_motion(
    ict_dataset,  # type: ignore[no-untyped-def]
) -> None:
    landmarks = ict.load_landmarks(ict_dir())
    take, truth, _, meshes = _synthetic_take(ict_dataset, landmarks)
    marks = {n: int(landmarks[k]) for n, k in lomo.ANIMFACE_IBUG.items()}
    got = lomo.retarget(take, ict_dataset.neutral, ict.face_triangles(ict_dataset), marks)
    held = [got.names.index("Mouth_Lend"), got.names.index("extra3")]

    class Oracle:  # returns the meshes the take was made from
        def solve(self, frames, **_):  # type: ignore[no-untyped-def]
            assert frames.shape == (6, truth.shape[1] - 1, 3)
            return SimpleNamespace(vertices=meshes)

    def methods(ds, rest, frames):  # type: ignore[no-untyped-def]
        return {"rest": lomo.Rest(ds), "fit": Oracle()}

    scores = lomo.lomo(ict_dataset, got, held, methods)
    for j in held:
        name = got.names[j]
        moved = np.linalg.norm(truth[:, j] - truth[0, j], axis=1)
        np.testing.assert_allclose(scores.errors["rest"][name], moved, atol=1e-8)
        assert moved.max() > 0.05  # the held-out markers move
        assert scores.errors["fit"][name].max() < 1e-8
    rows = lomo.rows([scores], "synthetic")
    assert [r["method"] for r in rows] == ["synthetic: rest", "synthetic: fit"]
    assert rows[1]["best_of"] == 2 and rows[0]["markers"] == 2 and rows[0]["frames"] == 6


def test_retarget_refuses_a_take_without_skull_markers_or_with_a_gap_at_rest() -> None:
    rng = np.random.default_rng(0)
    names = ["a", "b", "c", "d", "e"]
    pts = rng.normal(size=(3, 5, 3))
    take = RawTake(labels=names, points=pts, fps=60.0, units="cm", path="take.trc")
    verts = rng.normal(size=(4, 3))
    tris = np.array([[0, 1, 2]])
    with pytest.raises(InputError, match=r"take.trc: needs at least 3 of the skull markers"):
        lomo.retarget(take, verts, tris, {"a": 0, "b": 1, "c": 2, "d": 3})
    with pytest.raises(InputError, match=r"needs at least 4 landmark markers"):
        lomo.retarget(take, verts, tris, {"a": 0, "b": 1}, rigid=("a", "b", "c"))
    gap = pts.copy()
    gap[0, 3] = np.nan
    bad = RawTake(labels=names, points=gap, fps=60.0, units="cm", path="take.trc")
    with pytest.raises(InputError, match=r"frame 1 \(the rest frame\) misses d"):
        lomo.retarget(bad, verts, tris, {"a": 0, "b": 1, "c": 2, "e": 3}, rigid=("a", "b", "c"))


def _animface() -> list[Path]:
    takes = ict.animface(ict_dir().parent)
    if not takes:
        pytest.skip(f"no AnimFace takes in {ict_dir().parent / 'animface'}")
    return takes


def test_animface_takes_retarget_onto_ict_at_the_performers_scale_with_a_rigid_skull(
    ict_dataset,  # type: ignore[no-untyped-def]
) -> None:
    from lgi.io.takes import read_raw

    landmarks = ict.load_landmarks(ict_dir())
    marks = {n: int(landmarks[k]) for n, k in lomo.ANIMFACE_IBUG.items()}
    for path in _animface():
        got = lomo.retarget(
            read_raw(path), ict_dataset.neutral, ict.face_triangles(ict_dataset), marks
        )
        # The README: a similarity leaves ~1 cm on the landmarks (not ICT's face); the
        # forehead and nose bridge stay within a millimetre of rigid after stabilisation.
        assert 0.8 < got.scale < 0.95
        assert 0.9 < got.landmark_residual < 1.2
        assert np.median(got.stabilised_rms) < 0.1
        assert np.isfinite(got.frames).all() and got.frames.shape[1] == 41


def test_cli_lomo_scores_every_method_on_the_real_takes_and_each_beats_no_motion(
    tmp_path: Path,
) -> None:
    from lgi.app.cli import main

    _animface()
    out = tmp_path / "lomo"
    argv = ["evaluate", "--data", "ict", "--protocol", "lomo", "--frames", "20"]
    assert (
        main([*argv, "--held-out", "2", "--ict-dir", str(ict_dir()), "--out", str(out), "-q"]) == 0
    )
    text = (out / "results.md").read_text()
    assert "## Each held-out marker" in text and not (out / "panel.png").exists()
    with open(out / "results.csv") as fh:
        rows = {r["method"]: float(r["mean"]) for r in csv.DictReader(fh)}
    for label in ("cheeks", "nose", "all takes"):
        rest = rows[f"{label}: no motion"]
        others = [v for k, v in rows.items() if k.startswith(f"{label}: ") and "no motion" not in k]
        assert len(others) == 9 and max(others) < rest


def test_cli_lomo_names_a_take_without_the_animface_markers(tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    from lgi.app.cli import main

    d = ict_dir()
    trc = tmp_path / "other.trc"
    trc.write_text(
        "PathFileType\t4\t(X/Y/Z)\tother.trc\n"
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n"
        "60\t60\t2\t3\tcm\t60\t1\t2\n"
        "Frame#\tTime\tA\t\t\tB\t\t\tC\n\t\tX1\tY1\tZ1\tX2\tY2\tZ2\tX3\tY3\tZ3\n\n"
        "1\t0\t0\t0\t0\t1\t0\t0\t0\t1\t0\n2\t0.0167\t0\t0\t0\t1\t0\t0\t0\t1\t0\n"
    )
    argv = ["evaluate", "--data", "ict", "--protocol", "lomo", "--take", str(trc)]
    assert main([*argv, "--ict-dir", str(d), "--out", str(tmp_path / "o"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("lgi: error: ") and "other.trc: needs at least 3 of the skull" in err
