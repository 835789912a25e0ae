"""A take the wrong size for its model (a wrong unit label, an empty one) is refused before the
solve, naming the factor and the unit the numbers look like; a right one passes whatever the
head's pose, the dropouts, a few swapped or spiking markers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from lgi.app import cli
from lgi.errors import InputError
from lgi.solve.placement import SCALE_TOLERANCE, check_scale, take_scale
from pipeline_files import build_actor, write_c3d


def _posed(rest: np.ndarray, scale: float, seed: int, dropout: float) -> np.ndarray:
    """Ten frames of `rest` scaled, rotated and moved at random, with 0.5 % noise of the
    layout's size and a `dropout` share of samples missing."""
    rng = np.random.default_rng(seed)
    size = float(np.linalg.norm(rest.max(0) - rest.min(0)))
    frames = []
    for _ in range(10):
        r = Rotation.random(random_state=rng).as_matrix()
        x = scale * rest @ r.T + rng.normal(0, 50 * size, 3)
        x += rng.normal(0, 0.005 * size * scale, x.shape)
        x[rng.random(len(x)) < dropout] = np.nan
        frames.append(x)
    return np.array(frames)


@settings(max_examples=40, deadline=None)
@given(
    scale=st.floats(0.7, 1.4),
    seed=st.integers(0, 2**32 - 1),
    dropout=st.floats(0.0, 0.4),
)
def test_any_pose_of_a_face_sized_take_passes_and_its_factor_is_measured(
    sample, scale: float, seed: int, dropout: float
) -> None:  # type: ignore[no-untyped-def]
    frames = _posed(sample.markers_rest, scale, seed, dropout)
    fit = check_scale(frames, sample.markers_rest, path="t", file_units="cm", model_units="cm")
    assert fit is not None
    assert fit.factor == pytest.approx(scale, rel=0.02)


@settings(max_examples=40, deadline=None)
@given(
    wrong=st.sampled_from([10.0, 0.1, 100.0, 0.01, 1000.0, 2.54, 1 / 2.54, 25.4, 0.3048]),
    actor=st.floats(0.85, 1.15),
    seed=st.integers(0, 2**32 - 1),
    dropout=st.floats(0.0, 0.4),
)
def test_a_unit_mistake_is_refused_whatever_the_pose_and_dropouts(
    sample, wrong: float, actor: float, seed: int, dropout: float
) -> None:  # type: ignore[no-untyped-def]
    frames = _posed(sample.markers_rest, wrong * actor, seed, dropout)
    with pytest.raises(InputError, match=r"t: the markers are [\d.e+]+ x the size"):
        check_scale(frames, sample.markers_rest, path="t", file_units="cm", model_units="cm")


@pytest.mark.parametrize(
    ("factor", "unit"), [(10.0, "mm"), (0.1, "dm"), (1 / 2.54, "in"), (100.0, None)]
)
def test_the_refusal_names_the_unit_the_numbers_look_like(
    sample, factor: float, unit: str | None
) -> None:  # type: ignore[no-untyped-def]
    frames = _posed(sample.markers_rest, factor, 0, 0.0)
    with pytest.raises(InputError) as e:
        check_scale(frames, sample.markers_rest, path="t", file_units="cm", model_units="cm")
    text = str(e.value)
    assert f"{factor:.3g} x the size" in text
    if unit is None:  # numbers 100 x too big for cm: a unit of 0.1 mm, which none is
        assert "no length unit explains the factor" in text
    else:
        assert f"look like {unit}: pass --take-units {unit}" in text


def test_swapped_and_spiking_markers_do_not_move_the_factor(sample) -> None:  # type: ignore[no-untyped-def]
    frames = _posed(sample.markers_rest, 1.0, 3, 0.05)
    frames[:, [3, 40]] = frames[:, [40, 3]]  # a swapped pair
    frames[:, 7] *= 100.0  # a marker far off
    fit = take_scale(frames, sample.markers_rest)
    assert fit is not None and fit.factor == pytest.approx(1.0, abs=0.03)


def test_too_few_markers_gives_no_factor_and_no_refusal(sample) -> None:  # type: ignore[no-untyped-def]
    frames = _posed(sample.markers_rest, 10.0, 1, 0.0)
    frames[:, 3:] = np.nan
    assert take_scale(frames, sample.markers_rest) is None


def test_the_tolerance_lies_between_real_faces_and_the_nearest_unit_mistake() -> None:
    assert 1.2 < SCALE_TOLERANCE < 2.54


# --- the command line, on files ---------------------------------------------------------------


@pytest.fixture(scope="module")
def actor(tmp_path_factory, sample):  # type: ignore[no-untyped-def]
    d = tmp_path_factory.mktemp("placement")
    a, model = build_actor(d, sample)
    return d, a, model


def _run(capsys, *argv: str | Path) -> tuple[int, str, str]:  # type: ignore[no-untyped-def]
    code = cli.main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_a_c3d_in_mm_labelled_cm_is_refused_by_solve_and_flagged_by_info(
    actor, sample, capsys, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    _, a, model = actor
    take = tmp_path / "mm_as_cm.c3d"
    write_c3d(take, 10.0 * np.asarray(sample.performance[:20]), a.names, 30.0, "cm")
    code, _, err = _run(capsys, "solve", model, take, "-o", tmp_path / "o.npz", "-q")
    assert code == 2
    assert "the markers are 10 x the size of the model's layout" in err
    assert "The file says cm, but its numbers look like mm: pass --take-units mm" in err
    assert not (tmp_path / "o.npz").exists()
    code, out, _ = _run(capsys, "info", take, "--model", model)
    assert code == 0 and "size: refused by lgi solve" in out and "look like mm" in out
    # Stating the true unit solves it, at the right size.
    code, _, err = _run(
        capsys, "solve", model, take, "-o", tmp_path / "o.npz", "-q", "--take-units", "mm"
    )
    assert code == 0, err
    code, out, _ = _run(capsys, "info", take, "--model", model, "--take-units", "mm")
    assert "size: 1 x the model's layout" in out and "matches" in out


def test_a_c3d_with_an_empty_unit_in_mm_is_refused_and_asks_for_take_units(
    actor, sample, capsys, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    _, a, model = actor
    take = tmp_path / "silent.c3d"
    write_c3d(take, 10.0 * np.asarray(sample.performance[:20]), a.names, 30.0, "")
    code, _, err = _run(capsys, "solve", model, take, "-o", tmp_path / "o.npz", "-q")
    assert code == 2
    assert "The file gives no unit, so it was read in the model's (cm)" in err
    assert "--take-units mm" in err
