"""Fuzzing the Python API with hypothesis (docs/reliability.md): frames for every method,
dataset arrays, OBJ text, model-file bytes (with the checksum recomputed or not), count and
noise arguments and build configs. Each input has an oracle: what the policy says it must give
(refused with an `lgi` exception, or solved to finite output), so nonsense that is silently
accepted fails as surely as a crash. Inputs are never modified.

`LGI_FUZZ_EXAMPLES` sets the examples per test (default: the hypothesis profile's, a short
budget in the test command); `LGI_FUZZ_REPORT` names a JSON file that receives the tally of
outcomes per test (scripts/fuzz.sh writes and sums it)."""

from __future__ import annotations

import atexit
import json
import os
import struct
import warnings
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import lgi
from lgi import _lgi
from lgi.lab.baselines import BlendshapeFit, DisplacementInterpolation, LgiRbf
from lgi.lab.sample import make_sample
from lgi.lab.sample import sample_dataset as dataset_of

FUZZ = settings(
    max_examples=int(os.environ.get("LGI_FUZZ_EXAMPLES", "0")) or settings().max_examples,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)

TALLY: dict[str, Counter[str]] = {}


def _count(test: str, outcome: str) -> None:
    TALLY.setdefault(test, Counter())[outcome] += 1


@atexit.register
def _write_report() -> None:
    path = os.environ.get("LGI_FUZZ_REPORT")
    if path and TALLY:
        Path(path).write_text(json.dumps({k: dict(v) for k, v in TALLY.items()}, indent=1))


_STATE: dict[str, Any] = {}


def _small() -> tuple[Any, Any, lgi.Model]:
    """The small sample (1,379 vertices, 43 shapes, 106 markers), its dataset and model; built
    once (hypothesis runs examples many times inside one test)."""
    if "small" not in _STATE:
        s = make_sample(0, resolution=40, num_frames=4)
        d = dataset_of(s)
        _STATE["small"] = (s, d, lgi.Model.build(d, s.markers_rest))
    return _STATE["small"]  # type: ignore[no-any-return]


def _method(name: str) -> Any:
    key = "method-" + name
    if key not in _STATE:
        s, d, model = _small()
        _STATE[key] = {
            "lgi": lambda: model,
            "displacement": lambda: DisplacementInterpolation(d, s.markers_rest),
            "blendshape": lambda: BlendshapeFit(d, s.markers_rest),
            "lgi-rbf": lambda: LgiRbf(d, s.markers_rest),
        }[name]()
    return _STATE[key]


# Values a coordinate may take: mostly a small offset, sometimes absurd.
WILD = st.one_of(
    st.floats(-0.5, 0.5),
    st.sampled_from(
        [np.nan, np.inf, -np.inf, 1e308, -1e308, 1e200, 1e154, 1e30, -1e30, 1e5, 1e3, -1e3, 0.0]
    ),
    st.floats(allow_nan=True, allow_infinity=True),
)


@st.composite
def marker_frames(draw: st.DrawFn) -> np.ndarray:
    s, _, _ = _small()
    rest = s.markers_rest
    nf = draw(st.integers(1, 3))
    frames = np.repeat(rest[None], nf, axis=0)
    frames += draw(st.floats(0.0, 0.3)) * np.random.default_rng(
        draw(st.integers(0, 2**32 - 1))
    ).standard_normal(frames.shape)
    edits = draw(
        st.lists(
            st.tuples(
                st.integers(0, nf - 1), st.integers(0, rest.shape[0] - 1), st.integers(0, 2), WILD
            ),
            max_size=6,
        )
    )
    for f, b, c, v in edits:
        frames[f, b, c] = v if not np.isfinite(v) or abs(v) > 10 else frames[f, b, c] + v
    if draw(st.booleans()):  # drop whole rows (missing markers), sometimes nearly all
        drop = draw(st.lists(st.integers(0, rest.shape[0] - 1), max_size=rest.shape[0]))
        frames[draw(st.integers(0, nf - 1)), drop] = np.nan
    return frames


def _must_refuse(frames: np.ndarray, rest: np.ndarray, diagonal: float) -> str | None:
    """Why the policy (docs/reliability.md) refuses `frames`, or None: an infinite coordinate,
    a present marker beyond MAGNITUDE_LIMIT face sizes of the rest layout's centre, or fewer
    than 3 markers present in a frame. Written from the policy, independently of the core."""
    if np.isinf(frames).any():
        return "infinite"
    centre = (rest.min(axis=0) + rest.max(axis=0)) / 2
    present = ~np.isnan(frames).any(axis=2)
    with np.errstate(over="ignore", invalid="ignore"):  # 1e308 squared is inf: too far
        dist = np.linalg.norm(np.where(present[..., None], frames, centre) - centre, axis=2)
    if (dist > _lgi.MAGNITUDE_LIMIT * diagonal).any():
        return "too far"
    if (present.sum(axis=1) < 3).any():
        return "too few"
    return None


@pytest.mark.parametrize("method", ["lgi", "displacement", "blendshape", "lgi-rbf"])
@FUZZ
@given(frames=marker_frames())
def test_fuzzed_frames_are_refused_by_the_policy_or_solved_to_finite_output(
    method: str, frames: np.ndarray
) -> None:
    s, _, model = _small()
    solver = _method(method)
    given_frames = frames.copy()
    why = _must_refuse(frames, s.markers_rest, model.diagonal)
    name = f"frames[{method}]"
    try:
        res = solver.solve(frames, quiet=True)
    except lgi.InputError as e:
        np.testing.assert_array_equal(frames, given_frames)
        assert why is not None, f"refused input the policy accepts: {e}"
        _count(name, "refused")
        return
    np.testing.assert_array_equal(frames, given_frames)
    assert why is None, f"silently accepted nonsense ({why})"
    assert np.isfinite(res.vertices).all()
    assert np.isfinite(res.bundle_residuals).all()
    _count(name, "solved")


@st.composite
def dataset_arrays(draw: st.DrawFn) -> dict[str, Any]:
    v = draw(st.integers(0, 8))
    neutral = (
        np.asarray(draw(st.lists(WILD, min_size=3 * v, max_size=3 * v)), dtype=np.float64).reshape(
            v, 3
        )
        if v
        else np.zeros((0, 3))
    )
    if draw(st.booleans()) and v >= 3:  # mostly well-formed positions
        neutral = np.random.default_rng(draw(st.integers(0, 99))).random((v, 3))
    t = draw(st.integers(0, 6))
    tris = np.asarray(
        draw(st.lists(st.integers(-2, v + 1), min_size=3 * t, max_size=3 * t)), dtype=np.int64
    ).reshape(t, 3)
    if draw(st.booleans()) and v >= 3:  # mostly a valid fan of triangles
        tris = np.array([[0, k, k + 1] for k in range(1, v - 1)], dtype=np.int64)
    ns = draw(st.integers(0, 3))
    shapes = np.asarray(
        draw(st.lists(WILD, min_size=ns * v * 3, max_size=ns * v * 3)), dtype=np.float64
    ).reshape(ns, v, 3)
    if draw(st.booleans()):  # mostly small displacements
        shapes = np.clip(np.nan_to_num(shapes), -1, 1)
    out: dict[str, Any] = {"neutral": neutral, "triangles": tris, "shapes": shapes}
    if ns:
        out["names"] = [f"s{k}" for k in range(ns)]
    if draw(st.booleans()):
        out["uvs"] = np.random.default_rng(draw(st.integers(0, 99))).random((v, 2))
        out["uv_triangles"] = tris.copy()
    return out


@FUZZ
@given(arrays=dataset_arrays())
def test_fuzzed_dataset_arrays_make_a_valid_dataset_or_an_lgi_error(arrays: dict[str, Any]) -> None:
    copies = {k: a.copy() for k, a in arrays.items()}
    try:
        d = lgi.Dataset.from_arrays(**arrays)
    except lgi.LgiError:
        _count("dataset arrays", "refused")
        return
    finally:
        for k, a in arrays.items():
            np.testing.assert_array_equal(a, copies[k])
    neutral = np.asarray(d.neutral)
    assert np.isfinite(neutral).all() and np.isfinite(np.asarray(d.shapes)).all()
    tri = np.asarray(d.triangles)
    assert tri.size == 0 or (tri.min() >= 0 and tri.max() < d.num_vertices)
    _count("dataset arrays", "accepted")


OBJ_LINE = st.one_of(
    st.builds(lambda xs: "v " + " ".join(map(str, xs)), st.lists(WILD, max_size=4)),
    st.builds(lambda xs: "vt " + " ".join(map(str, xs)), st.lists(st.floats(-1, 2), max_size=3)),
    st.builds(
        lambda xs: "f " + " ".join(xs),
        st.lists(
            st.sampled_from(
                ["1", "2", "3", "4", "-1", "0", "9", "1/1", "2/2", "3/3", "1//1", "x", "/"]
            ),
            max_size=5,
        ),
    ),
    st.sampled_from(["f 1 2 3", "f 3 2 1", "f -1 -2 -3", "v 0.5 0.5 0.1", "# c", "g x", ""]),
    st.text(max_size=12),
)


@FUZZ
@given(lines=st.lists(OBJ_LINE, max_size=16))
def test_fuzzed_obj_text_reads_as_a_valid_dataset_or_a_dataset_error_naming_the_file(
    tmp_path_factory: pytest.TempPathFactory, lines: list[str]
) -> None:
    p = tmp_path_factory.mktemp("obj") / "fuzz.obj"
    body = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n" + "\n".join(lines) + "\n"
    p.write_text(body, encoding="utf-8", errors="replace")
    try:
        d = lgi.Dataset.from_obj(p)
    except lgi.DatasetError as e:
        assert "fuzz.obj" in str(e)
        _count("obj text", "refused")
        return
    assert np.isfinite(np.asarray(d.neutral)).all()
    _count("obj text", "accepted")


def _model_bytes(tmp: Path) -> bytes:
    if "bytes" not in _STATE:
        p = tmp / "small.lgi"
        _small()[2].save(p)
        _STATE["bytes"] = p.read_bytes()
    return _STATE["bytes"]  # type: ignore[no-any-return]


def _resum(data: bytearray) -> None:
    """The version 3 checksum (docs/file-formats.md), recomputed after an edit."""
    mask, prime = (1 << 64) - 1, 0x0000_0100_0000_01B3
    payload = bytes(data[28:])
    lanes = [0xCBF29CE484222325, 0x84222325CBF29CE4, 0x9CE484222325CBF2, 0x2325CBF29CE48422]
    n = len(payload) // 32 * 32
    words = np.frombuffer(payload[:n], dtype="<u8").reshape(-1, 4).astype(object)
    for k in range(4):
        for w in words[:, k]:
            lanes[k] = ((lanes[k] ^ int(w)) * prime) & mask
    h = (len(payload) * prime) & mask
    for lane in lanes:
        h = ((h ^ lane) * prime) & mask
        h ^= h >> 29
    for b in payload[n:]:
        h = ((h ^ b) * prime) & mask
    data[20:28] = struct.pack("<Q", h)


WORD = st.one_of(
    st.integers(0, 64).map(lambda i: struct.pack("<Q", i)),
    st.sampled_from([2**64 - 1, 2**32 - 1, 2**63]).map(lambda i: struct.pack("<Q", i)),
    st.sampled_from([0.0, -1.0, 1e30, 1e300, float("nan"), float("inf"), 0.5]).map(
        lambda x: struct.pack("<d", x)
    ),
    st.binary(min_size=8, max_size=8),
)


@FUZZ
@given(
    edits=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), WORD), min_size=1, max_size=3),
    resum=st.booleans(),
)
def test_fuzzed_model_files_load_as_valid_models_or_raise_model_format_error(
    tmp_path_factory: pytest.TempPathFactory, edits: list[tuple[float, bytes]], resum: bool
) -> None:
    tmp = tmp_path_factory.mktemp("model")
    data = bytearray(_model_bytes(tmp))
    payload = len(data) - 28
    for at, word in edits:
        i = 28 + int(at * (payload - 8)) // 8 * 8
        data[i : i + 8] = word
    if resum:
        _resum(data)
    p = tmp / "fuzz.lgi"
    p.write_bytes(bytes(data))
    try:
        m = lgi.Model.load(p)
    except lgi.ModelFormatError:
        _count("model file", "refused")
        return
    rest = _small()[0].markers_rest
    assert m.num_bundles == rest.shape[0]  # a count edit cannot leave the arrays consistent
    res = m.solve(rest[None], quiet=True)
    assert np.isfinite(res.vertices).all()
    _count("model file", "loaded")


ARG = st.one_of(
    st.integers(-5, 12),
    st.sampled_from(
        [2**64, 2**63, -(2**70), True, None, "3", 2.5, float("nan"), float("inf"), -0.0, 1e300]
    ),
    st.floats(allow_nan=True, allow_infinity=True),
)


@FUZZ
@given(window=ARG, noise=ARG, min_shapes=ARG)
def test_fuzzed_arguments_are_accepted_or_named_input_errors(
    window: Any, noise: Any, min_shapes: Any
) -> None:
    s, d, model = _small()
    frames = s.markers_rest[None]
    try:
        res = model.solve(frames, smooth_window=window, marker_noise=noise, quiet=True)
        assert np.isfinite(res.vertices).all()
        _count("arguments", "accepted")
    except lgi.InputError as e:
        assert "smooth_window" in str(e) or "marker_noise" in str(e), str(e)
        _count("arguments", "refused")
    try:
        valid = isinstance(min_shapes, int) and not isinstance(min_shapes, bool)
        if valid and 0 <= min_shapes < 2**64:
            if min_shapes <= 60:  # larger counts are legal too (all pairs), only slower
                d.augmented(min_shapes)
        else:
            with pytest.raises(lgi.InputError, match="min_shapes"):
                d.augmented(min_shapes)
    except lgi.LgiError:
        pass  # refused for the dataset (e.g. too few shapes to combine): named by the core


CONFIG_VALUE = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-3, 300),
    st.sampled_from([0, 1e-12, 1e12, 2**64]),
)
FIELDS = [
    "surface_tolerance",
    "prune_motion",
    "duplicate_distance",
    "tet_neighbours",
    "max_tets",
    "min_quality",
    "max_edge",
    "containment_eps",
    "projection_candidates",
    "temporal_weight",
    "detour_ratio",
]


@FUZZ
@given(changes=st.dictionaries(st.sampled_from(FIELDS), CONFIG_VALUE, max_size=3))
def test_fuzzed_build_configs_build_a_model_that_solves_finite_or_raise_an_lgi_error(
    changes: dict[str, Any],
) -> None:
    s, d, _ = _small()
    try:
        cfg = lgi.BuildConfig(**changes)
        with warnings.catch_warnings(record=True) as warned:
            warnings.simplefilter("always", lgi.LgiWarning)
            model = lgi.Model.build(d, s.markers_rest, config=cfg)
    except (lgi.LgiError, TypeError, OverflowError) as e:
        # A float for an int field is a TypeError of the binding's signature (named there).
        assert not isinstance(e, (TypeError, OverflowError)) or any(f in str(e) for f in changes), (
            str(e)
        )
        _count("build config", "refused")
        return
    res = model.solve(s.markers_rest[None], quiet=True)
    assert np.isfinite(res.vertices).all()
    _count("build config", "built with a warning" if warned else "built")


# -- takes on set: TRC frame numbering, cut rows, corrupt C3D bytes, the size check -------------


@FUZZ
@given(
    steps=st.lists(st.integers(-2, 4), min_size=1, max_size=12),
    cut=st.integers(0, 40),
)
def test_fuzzed_trc_frame_numbers_and_cut_rows_read_in_order_or_raise_input_error(
    tmp_path_factory: pytest.TempPathFactory, steps: list[int], cut: int
) -> None:
    from lgi.io import takes

    numbers = [1]
    for s in steps:
        numbers.append(numbers[-1] + s)
    lines = [
        "PathFileType\t4\t(X/Y/Z)\tf.trc",
        "DataRate\tNumFrames\tUnits",
        f"100\t{len(numbers)}\tmm",
        "Frame#\tTime\ta\t\t\tb\t\t",
        "\t\tX1\tY1\tZ1\tX2\tY2\tZ2",
        "",
    ]
    lines += [f"{k}\t{(k - 1) / 100:.4f}\t1\t2\t3\t4\t5\t6" for k in numbers]
    text = "\n".join(lines)
    p = tmp_path_factory.mktemp("trc") / "f.trc"
    p.write_text(text[: len(text) - cut])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", lgi.LgiWarning)
            raw = takes.read_raw(p)
    except lgi.InputError as e:
        assert str(p) in str(e)
        _count("trc", "refused")
        return
    # Read: the first and last rows are frames, gaps between them missing frames.
    present = ~np.isnan(raw.points).any(axis=2).all(axis=1)
    assert present[0] and present[-1] and present.sum() <= len(numbers)
    _count("trc", "read")


@FUZZ
@given(
    edits=st.lists(
        st.tuples(st.floats(0, 1, exclude_max=True), st.binary(min_size=1, max_size=4)),
        min_size=1,
        max_size=4,
    )
)
def test_fuzzed_c3d_bytes_read_as_a_take_or_raise_input_error(
    tmp_path_factory: pytest.TempPathFactory, edits: list[tuple[float, bytes]]
) -> None:
    from lgi.io import takes
    from pipeline_files import write_c3d

    tmp = tmp_path_factory.mktemp("c3d")
    good = tmp / "good.c3d"
    frames = np.arange(5 * 4 * 3, dtype=np.float64).reshape(5, 4, 3)
    write_c3d(good, frames, ["a", "b", "c", "d"], 100.0, "mm")
    data = bytearray(good.read_bytes())
    for at, b in edits:
        i = int(at * (len(data) - len(b)))
        data[i : i + len(b)] = b
    p = tmp / "fuzz.c3d"
    p.write_bytes(bytes(data))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", lgi.LgiWarning)
            raw = takes.read_raw(p)
    except lgi.InputError as e:
        assert str(p) in str(e) and "ignoreBadFormatting" not in str(e)
        _count("c3d", "refused")
        return
    assert raw.points.ndim == 3 and raw.points.shape[2] == 3
    assert len(raw.labels) == raw.points.shape[1]
    _count("c3d", "read")


@FUZZ
@given(
    values=st.lists(
        st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=3 * 6, max_size=3 * 6
    ),
    frames=st.integers(1, 3),
)
def test_fuzzed_takes_pass_the_size_check_or_raise_input_error(
    values: list[float], frames: int
) -> None:
    from lgi.solve.placement import check_scale

    rest = _small()[0].markers_rest[:6]
    x = np.tile(np.asarray(values, dtype=np.float64).reshape(1, 6, 3), (frames, 1, 1))
    x[np.isinf(x).any(axis=2)] = np.nan  # the magnitude policy refuses infinities first
    try:
        fit = check_scale(x, rest, path="t", file_units="cm", model_units="cm")
    except lgi.InputError as e:
        assert "x the size of the model's layout" in str(e)
        _count("size check", "refused")
        return
    assert fit is None or np.isfinite(fit.factor)
    _count("size check", "passed")
