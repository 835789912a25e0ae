"""Bad markers named: a swapped label pair and a spiking marker planted in a capture of ICT
driven by a real Live Link recording are named with their frames, by `lgi.solve.diagnose` and by
`lgi solve` / `lgi info` on the command line; a clean take of the same capture is not
flagged."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from lgi.app import cli
from lgi.solve.diagnose import Finding, diagnose, face_size, summary
from pipeline_files import write_solve


@pytest.fixture(scope="module")
def capture(ict_dataset, ict_markers, ict_path):  # type: ignore[no-untyped-def]
    """300 frames of ICT driven by the shared recording `jmtechart_myslate_3`, 0.5 mm noise,
    2 % dropouts, seed 1."""
    from lgi.io.livelink import read_livelinkface
    from lgi.lab import ict
    from lgi.lab.capture import make_capture

    rec = ict.livelinkface(ict_path.parent)
    curves = read_livelinkface(next(p for p in rec if "jmtechart" in p.name))
    w = curves.for_dataset(ict_dataset.names)[:300]
    return make_capture(
        ict_dataset, w, ict_markers, sigma=0.05, dropout=0.02, holdout=0, seed=1, jaw=None
    ).frames


def _planted(frames: np.ndarray) -> np.ndarray:
    x = frames.copy()
    x[100:150, [12, 47]] = x[100:150, [47, 12]]  # labels swapped for 50 frames
    x[200:203, 33] += [0.0, 0.0, 1.5]  # a 1.5 cm spike, 3 frames
    return x


@pytest.mark.parametrize("noise", [None, 0.05])
def test_a_swapped_pair_and_a_spike_are_named_with_their_frames(
    ict_model, capture, noise: float | None
) -> None:  # type: ignore[no-untyped-def]
    x = _planted(capture)
    res = ict_model.solve(x, marker_noise=noise, quiet=True)
    names = list(ict_model.marker_names)
    found = diagnose(res.bundle_residuals, res.missing, names, size=ict_model.diagonal, markers=x)
    assert found[0] == Finding("swap", ("m012", "m047"), 100, 149, found[0].worst)
    spikes = [f for f in found if f.kind == "spike"]
    assert [(f.markers, f.first, f.last) for f in spikes] == [(("m033",), 200, 202)]
    assert len(found) == 2


@pytest.mark.parametrize("spike", [1.0, 0.5])
def test_a_noise_free_take_read_at_round_off_names_a_spike_by_its_track_as_an_exact_solve(
    ict_dataset, ict_markers, ict_path, ict_model, spike: float
) -> None:  # type: ignore[no-untyped-def]
    import warnings

    import lgi
    from lgi.io.livelink import read_livelinkface
    from lgi.lab import ict
    from lgi.lab.capture import make_capture
    from lgi.solve.diagnose import FLOOR, NOISE_SIGMAS

    rec = ict.livelinkface(ict_path.parent)
    curves = read_livelinkface(next(p for p in rec if "jmtechart" in p.name))
    w = curves.for_dataset(ict_dataset.names)[:300]
    clean = make_capture(
        ict_dataset, w, ict_markers, sigma=0.0, dropout=0.02, holdout=0, seed=1, jaw=None
    ).frames
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the reading of a noise-free take warns so
        sigma = lgi.estimate_marker_noise(clean, ict_model)
    # The noise read is round-off, under any a residual could count at.
    assert 0.0 < sigma < FLOOR * ict_model.diagonal / NOISE_SIGMAS
    names = list(ict_model.marker_names)

    def found(x: np.ndarray) -> list[Finding]:
        res = ict_model.solve(x, marker_noise=sigma, repair=False, quiet=True)
        return diagnose(
            res.bundle_residuals, res.missing, names, size=ict_model.diagonal, markers=x,
            noise=sigma,
        )  # fmt: skip

    assert [f for f in found(clean) if f.fault] == []
    x = clean.copy()
    # 1 cm (a jump of the track) or 0.5 cm (under the 0.95 cm a track's jump must be: a jump
    # against its neighbours) for 3 frames: the solve interpolates it exactly.
    x[200:203, 33] += [0.0, 0.0, spike]
    assert [(f.kind, f.markers, f.first, f.last) for f in found(x) if f.fault] == [
        ("spike", ("m033",), 200, 202)
    ]


@pytest.mark.parametrize("noise", [None, 0.05])
def test_the_clean_capture_is_not_flagged(ict_model, capture, noise: float | None) -> None:  # type: ignore[no-untyped-def]
    res = ict_model.solve(capture, marker_noise=noise, quiet=True)
    names = list(ict_model.marker_names)
    assert (
        diagnose(res.bundle_residuals, res.missing, names, size=ict_model.diagonal, markers=capture)
        == []
    )


def test_residual_outliers_alone_name_a_marker_when_the_take_is_not_kept() -> None:
    rng = np.random.default_rng(0)
    r = np.abs(rng.normal(0.01, 0.003, (80, 6)))
    r[30:40, 4] = 0.5  # a marker the solve corrected hard for 10 frames
    missing = np.zeros_like(r, dtype=bool)
    missing[35, 4] = True  # a dropout inside the range does not split it
    found = diagnose(r, missing, list("abcdef"), size=20.0)
    assert found == [Finding("off", ("e",), 30, 39, 0.5)]
    lines = summary(r, missing, list("abcdef"), found, start=1001, units="cm")
    assert "largest 0.5 cm (e at time code 1031)" in lines[0]
    assert lines[1] == "marker off: e, time codes 1031-1040 (residual up to 0.5 cm)"


def test_a_finding_whose_samples_were_all_solved_as_missing_says_so_and_never_nan() -> None:
    nan = float("nan")
    assert (
        Finding("spike", ("m033",), 200, 202, nan).describe(0, "cm")
        == "spike: m033, time codes 200-202 (no residual: solved as missing)"
    )
    assert (
        Finding("swap", ("a", "b"), 3, 9, nan)
        .describe()
        .endswith("(no residual: solved as missing)")
    )
    for kind in ("off", "gap"):
        assert "nan" not in Finding(kind, ("m1",), 1, 4, nan).describe(10, "cm")
    # A residual that is there is given as before.
    assert Finding("spike", ("m033",), 5, 5, 0.5).describe(0, "cm") == (
        "spike: m033, time code 5 (residual up to 0.5 cm)"
    )


def _skin(frames: int = 120, markers: int = 16, seed: int = 0, noise: float = 0.02) -> np.ndarray:
    """Markers on a grid (2 cm apart) carried by a smooth non-rigid motion, `noise` per
    coordinate."""
    rng = np.random.default_rng(seed)
    grid = np.stack(np.meshgrid(np.arange(4.0), np.arange(4.0)), -1).reshape(-1, 2)[:markers] * 2
    rest = np.c_[grid, np.zeros(markers)]
    t = np.linspace(0.0, 2 * np.pi, frames)[:, None, None]
    wave = np.sin(t + 0.3 * rest[None, :, :1]) * np.array([0.0, 0.5, 0.3])  # skin moving
    return rest[None] + wave + rng.normal(0.0, noise, (frames, markers, 3))


def test_a_residual_shared_by_a_marker_moving_with_its_neighbours_is_a_gap_not_a_fault() -> None:
    """The model cannot follow marker 5 for frames 40-52 (its residual rises and falls), but the
    marker moves with its neighbours: the dataset's gap, named as such, no fault."""
    x = _skin()
    rng = np.random.default_rng(1)
    r = np.abs(rng.normal(0.01, 0.003, x.shape[:2]))
    r[40:53, 5] = 0.3 * np.sin(np.linspace(0.1, np.pi - 0.1, 13))
    found = diagnose(
        r, np.zeros(r.shape, bool), [f"m{k:02d}" for k in range(16)], size=20.0, markers=x
    )
    assert [(f.kind, f.markers, f.fault) for f in found] == [("gap", ("m05",), False)]
    assert found[0].describe(100, "cm").startswith("the dataset does not follow m05 at time codes")


def test_a_swap_made_across_both_markers_dropouts_is_named_as_that_swap() -> None:
    """Two markers 2 cm apart trade labels for frames 40-79, where one drops out for the 5
    frames before and the other for the 8 over the end (a label taken up again under the
    other's name): each shows one step of its own, read across its dropout against its
    neighbours, and the swap is named from each one's own edges. Before, a step across a
    dropout was read per frame elapsed (2 cm over 6 frames: no jump) and nothing was named."""
    x = _skin()
    a, b = 5, 6  # neighbours on the grid, 2 cm apart
    x[40:80, [a, b]] = x[40:80, [b, a]]
    x[35:40, a] = np.nan
    x[78:86, b] = np.nan
    missing = np.isnan(x).any(axis=2)
    rng = np.random.default_rng(1)
    r = np.where(missing, 0.0, np.abs(rng.normal(0.01, 0.003, x.shape[:2])))
    names = [f"m{k:02d}" for k in range(16)]
    found = diagnose(r, missing, names, size=20.0, markers=x)
    swaps = [(f.markers, f.first) for f in found if f.kind == "swap"]
    assert swaps == [(("m05", "m06"), 40)], found
    assert 79 <= next(f.last for f in found if f.kind == "swap") <= 85
    # Without the dropouts the same swap is named with its exact frames, as before.
    clean = _skin()
    clean[40:80, [a, b]] = clean[40:80, [b, a]]
    r0 = np.abs(rng.normal(0.01, 0.003, clean.shape[:2]))
    got = diagnose(r0, np.zeros(r0.shape, bool), names, size=20.0, markers=clean)
    assert [(f.kind, f.markers, f.first, f.last) for f in got] == [("swap", ("m05", "m06"), 40, 79)]


def _excursion_found(first: int, last: int) -> list[Finding]:
    """What `diagnose` finds where marker 5 jumps 1 cm away from its neighbours over frames
    first..last and back, its residual 3 mm there."""
    x = _skin()
    x[first : last + 1, 5] += [0.0, 0.0, 1.0]
    rng = np.random.default_rng(1)
    r = np.abs(rng.normal(0.01, 0.003, x.shape[:2]))
    r[first : last + 1, 5] = 0.3
    names = [f"m{k:02d}" for k in range(16)]
    return diagnose(r, np.zeros(r.shape, bool), names, size=20.0, markers=x)


def test_the_same_residual_with_the_marker_off_its_track_is_a_fault() -> None:
    """The same residual where marker 5 itself jumps 1 cm away from its neighbours for three
    frames and back (a spike), or for twelve (a marker off): faults."""
    for first, last, kind in ((40, 42, "spike"), (40, 51, "off")):
        found = _excursion_found(first, last)
        assert [(f.kind, f.markers, f.first, f.last) for f in found] == [
            (kind, ("m05",), first, last)
        ], found
        assert found[0].fault


def test_a_marker_off_its_track_from_the_takes_first_frame_or_to_its_last_is_a_gap() -> None:
    """The same 1 cm excursion of twelve frames, run from the take's first frame or to its
    last: one step off the track at most, as a blink the dataset cannot follow shows at a
    take's start, so the dataset's gap, not a fault; a three-frame spike there still is one."""
    frames = _skin().shape[0]
    cases = ((0, 11, "gap"), (frames - 12, frames - 1, "gap"), (0, 2, "spike"))
    for first, last, kind in cases:
        found = _excursion_found(first, last)
        assert [(f.kind, f.markers, f.first, f.last) for f in found] == [
            (kind, ("m05",), first, last)
        ], (first, last, found)


def test_a_neighbours_residual_over_a_spike_is_the_spikes_echo_not_a_gap() -> None:
    """A noise-aware solve spreads a spiking marker's correction to its neighbour: the
    neighbour's residual over the spike's frames is neither a fault nor a gap of the dataset."""
    names = [f"m{k:02d}" for k in range(16)]
    x = _skin()
    x[40:43, 5] += [0.0, 0.0, 1.0]
    rng = np.random.default_rng(1)
    r = np.abs(rng.normal(0.01, 0.003, x.shape[:2]))
    r[40:43, 5] = 0.6
    r[40:43, 6] = 0.2  # marker 6 is 2 cm away, a neighbour: the correction spread to it
    found = diagnose(r, np.zeros(r.shape, bool), names, size=20.0, markers=x)
    assert [(f.kind, f.markers) for f in found] == [("spike", ("m05",))]
    r[80:83, 6] = 0.2  # the same residual at frames of its own is the dataset's gap
    found = diagnose(r, np.zeros(r.shape, bool), names, size=20.0, markers=x)
    assert [(f.kind, f.markers, f.first) for f in found] == [
        ("spike", ("m05",), 40),
        ("gap", ("m06",), 80),
    ]


def test_held_out_shapes_are_gaps_and_planted_faults_are_still_named(
    ict_dataset, ict_markers, ict_path
) -> None:  # type: ignore[no-untyped-def]
    """ICT with a quarter of its shapes held out cannot follow every expression: what the
    noise-aware solve corrects there is the dataset's (no fault on the clean take), while a
    swap and a spike planted in the same take are named as faults."""
    import lgi
    from lgi.io.livelink import read_livelinkface
    from lgi.lab import ict
    from lgi.lab.capture import make_capture

    rec = ict.livelinkface(ict_path.parent)
    curves = read_livelinkface(next(p for p in rec if "alex" in p.name))
    w = curves.for_dataset(ict_dataset.names)[:600]
    take = make_capture(
        ict_dataset, w, ict_markers, sigma=0.02, dropout=0.02, holdout=0.25, seed=0, jaw=None
    )
    model = lgi.Model.build(take.dataset, ict_markers)
    names = list(model.marker_names)
    sigma = lgi.estimate_marker_noise(take.frames, model)

    def found(x: np.ndarray) -> list[Finding]:
        res = model.solve(x, marker_noise=sigma, repair=False, quiet=True)
        return diagnose(
            res.bundle_residuals, res.missing, names, size=model.diagonal, markers=x, noise=sigma
        )

    assert [f for f in found(take.frames) if f.fault] == []
    x = _planted(take.frames)
    faults = [(f.kind, f.markers, f.first, f.last) for f in found(x) if f.fault]
    assert ("swap", ("m012", "m047"), 100, 149) in faults
    assert ("spike", ("m033",), 200, 202) in faults
    assert len(faults) == 2, faults


def test_lgi_solve_prints_the_findings_and_lgi_info_names_them_from_the_file(
    ict_model, capture, tmp_path: Path, capsys
) -> None:  # type: ignore[no-untyped-def]
    x = _planted(capture)
    solved = write_solve(tmp_path / "take.npz", ict_model, x, 0.05, fps=60.0, start=1)
    assert cli.main(["info", str(solved)]) == 0
    out = capsys.readouterr().out
    assert "likely label swap: m012 <-> m047, time codes 101-150" in out
    assert "spike: m033, time codes 201-203" in out
    assert "residual median" in out and " cm" in out
    # The two planted faults lead, each at a time code of its own range: the swapped marker
    # that the noise-aware targets pull back to the fit (its neighbours do not share its 9 cm),
    # then the spike; the worst frames are the swap's.
    worst = re.search(r"worst markers \(largest residual\): (.*)", out)
    assert worst is not None
    lead = [m.groups() for m in re.finditer(r"(m\d{3}) [\d.]+ cm at (\d+)", worst.group(1))][:2]
    assert lead[0][0] == "m047" and 101 <= int(lead[0][1]) <= 150, lead
    assert lead[1][0] == "m033" and 201 <= int(lead[1][1]) <= 203, lead
    frames = re.search(r"worst frames \(time code, largest residual, marker\): (.*)", out)
    assert frames is not None
    for code, marker in re.findall(r"(\d+) [\d.]+ cm (m\d{3})", frames.group(1)):
        assert marker == "m047" and 101 <= int(code) <= 150, frames.group(1)


def test_a_noise_free_spike_against_the_neighbours_is_named_and_a_blink_easing_back_is_not() -> (
    None
):
    """Noise-free skin (the `_skin` grid, no noise, exact residuals) of a 47.5 cm face: marker
    9 is 0.5 cm off for frames 30-32, half the 0.95 cm a track's own jump must be; marker 5
    blinks at frame 60 (two frames down 0.9 cm against its neighbours, eased back over five),
    as an eyelid marker alone on its lid does. The spike leaves a settled track and comes back
    to it, off the take's own motion; the blink steps two frames running each way and eases
    back, off that motion at its edges too."""
    x = _skin(noise=0.0)
    x[30:33, 9] += [0.0, 0.5, 0.0]
    lid = np.array([0.45, 0.85, 0.9, 0.63, 0.34, 0.2, 0.1, 0.04])
    x[60 : 60 + lid.size, 5] -= lid[:, None] * [0.0, 1.0, 0.05]
    r = np.zeros(x.shape[:2])
    found = diagnose(
        r, np.zeros(r.shape, bool), [f"m{k:02d}" for k in range(16)], size=47.5, markers=x
    )
    assert [(f.kind, f.markers, f.first, f.last) for f in found] == [("spike", ("m09",), 30, 32)]
    x[30:33, 9] -= [0.0, 0.5, 0.0]
    assert diagnose(r, np.zeros(r.shape, bool), [f"m{k:02d}" for k in range(16)], size=47.5,
                    markers=x) == []  # fmt: skip


def test_a_noise_free_takes_blinks_on_a_lone_lid_marker_are_no_spikes_and_a_half_cm_one_is(
    ict_dataset, ict_path
) -> None:  # type: ignore[no-untyped-def]
    """The whole `alex_rom_4` recording on ICT (a quarter of its shapes held out), 160 random
    markers, noise-free, 2 % dropouts, read as an exact solve is (round-off residuals): the
    upper-lid marker `m072`, alone on its lid, steps 4-5 mm against its neighbours two frames
    running at each blink and eases back; such a blink's middle is back where it left
    within half its step (a spike's shape) and was named a spike four times until a spike had
    to leave a settled track and come back to one. A 0.5 cm spike (3 frames) is named."""
    from lgi.io.livelink import read_livelinkface
    from lgi.lab import ict
    from lgi.lab.capture import make_capture, random_layout

    curves = read_livelinkface(ict_path.parent / "livelinkface" / "alex_rom_4.csv")
    pos = random_layout(ict_dataset, 160, 1, np.arange(ict.NARROW_FACE))
    w = curves.for_dataset(ict_dataset.names)
    x = make_capture(
        ict_dataset, w, pos, sigma=0.0, dropout=0.02, holdout=0.25, seed=0, jaw=None
    ).frames
    names = [f"m{k:03d}" for k in range(160)]
    size = face_size(ict_dataset.neutral)  # the model's diagonal: 47.5 cm
    zero, missing = np.zeros(x.shape[:2]), np.isnan(x).any(axis=2)
    assert [f for f in diagnose(zero, missing, names, size=size, markers=x) if f.fault] == []
    x[2856:2859, 152] += [0.0, 0.5, 0.0]
    faults = [f for f in diagnose(zero, missing, names, size=size, markers=x) if f.fault]
    assert [(f.kind, f.markers, f.first, f.last) for f in faults] == [
        ("spike", ("m152",), 2856, 2858)
    ]


def _performance(frames: int = 400, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Markers on the `_skin` grid moved by three directions of motion (smooth) and a fast one
    that markers 5 and 6 carry together (a lid's blink: a two-frame pulse every 40 frames),
    0.02 noise; with that pulse's frames."""
    rng = np.random.default_rng(seed)
    rest = _skin(1, 16, seed)[0]
    t = np.arange(frames)[:, None] / 60.0
    dirs = rng.normal(size=(3, 16, 3))
    slow = np.c_[np.sin(2.1 * t), np.cos(1.3 * t), np.sin(0.7 * t + 1.0)]
    x = rest[None] + np.einsum("fk,kbi->fbi", slow, 0.4 * dirs)
    pulses = np.arange(20, frames - 5, 40)
    fast = np.zeros(frames)
    fast[pulses], fast[pulses + 1] = 1.0, 0.6
    x[:, 5] += fast[:, None] * [0.0, -0.8, 0.2]
    x[:, 6] += fast[:, None] * [0.0, -0.7, 0.3]
    return x + rng.normal(0.0, 0.02, x.shape), pulses


def test_take_deviations_are_each_markers_gaussian_conditional_given_the_others() -> None:
    """On a complete frame, a marker's deviation is its distance from the conditional mean
    given the frame's other markers under the Gaussian read from the other blocks of frames
    (mean, its directions above the noise's bulk edge with their variance less the noise's,
    white noise sigma): here conditioned by the explicit covariance, by numpy."""
    from lgi.solve.diagnose import FOLD_FRAMES, _take_deviations
    from lgi.solve.spectrum import shrinkage_factors

    x, _ = _performance()
    sigma = 0.02
    got = _take_deviations(x, sigma)
    assert got is not None
    f = x.shape[0]
    flat = x.reshape(f, -1)
    centred = flat - flat.mean(axis=0)
    fold = (np.arange(f) // FOLD_FRAMES) % 2
    for judged in (0, 1):
        seen = centred[fold != judged]
        _, sv, vt = np.linalg.svd(seen, full_matrices=False)
        n, p = seen.shape
        keep = (
            shrinkage_factors(sv / (np.sqrt(max(n - 1, p)) * sigma), min(n - 1, p) / max(n - 1, p))
            > 0
        )
        lam = np.maximum(sv[keep] ** 2 / (n - 1) - sigma**2, 0.0)
        cov = vt[keep].T @ np.diag(lam) @ vt[keep] + sigma**2 * np.eye(p)
        for frame in np.flatnonzero(fold == judged)[::25]:
            for k in (0, 5, 11):
                own = np.arange(3 * k, 3 * k + 3)
                rest = np.setdiff1d(np.arange(p), own)
                mean = cov[np.ix_(own, rest)] @ np.linalg.solve(
                    cov[np.ix_(rest, rest)], centred[frame, rest]
                )
                want = np.linalg.norm(centred[frame, own] - mean)
                np.testing.assert_allclose(got[frame, k], want, rtol=1e-6, atol=1e-9)


def test_skin_the_take_moves_so_elsewhere_is_a_gap_and_a_spike_the_solve_followed_is_named() -> (
    None
):
    """Markers 5 and 6 blink together: a residual over one blink on marker 5 (it leaves its
    four nearest markers' track and comes back) is the dataset's gap, since the take's own
    motion puts it there from marker 6. A 1 cm spike the solve followed (no residual) is
    named with its frames from the take alone; the same offset on half the markers at one
    frame is the face's own motion, no fault."""
    x, pulses = _performance()
    names = [f"m{k:02d}" for k in range(16)]
    rng = np.random.default_rng(2)
    r = np.abs(rng.normal(0.01, 0.003, x.shape[:2]))
    blink = int(pulses[3])
    r[blink : blink + 2, 5] = 0.3
    none = np.zeros(r.shape, bool)
    found = diagnose(r, none, names, size=20.0, markers=x, noise=0.02)
    assert [(f.kind, f.markers, f.first) for f in found] == [("gap", ("m05",), blink)], found
    spiked = x.copy()
    spiked[300:302, 9] += [1.0, 0.0, 0.0]
    r_clean = np.abs(rng.normal(0.01, 0.003, x.shape[:2]))
    found = diagnose(r_clean, none, names, size=20.0, markers=spiked, noise=0.02)
    assert [(f.kind, f.markers, f.first, f.last) for f in found] == [("spike", ("m09",), 300, 301)]
    face = x.copy()
    face[300, ::2] += [1.0, 0.0, 0.0]
    assert [
        f for f in diagnose(r_clean, none, names, size=20.0, markers=face, noise=0.02) if f.fault
    ] == []


def test_a_range_off_the_takes_motion_and_the_surface_needs_one_step_off_its_track_not_two() -> (
    None
):
    from lgi.solve.diagnose import _above_median, _leaves_track

    rng = np.random.default_rng(3)
    steps = np.abs(rng.normal(size=(200, 2)))  # marker 0's steps relative to its neighbours
    limit = _above_median(steps[:, 0], 8.0)
    steps[100, 0] = 2.0 * limit  # it steps off at frame 100 ...
    steps[104, 0] = 0.5 * limit  # ... and back at 104 within its noise
    assert not _leaves_track(steps, 0, 100, 103)  # both edges asked: a blink steps once
    assert _leaves_track(steps, 0, 100, 103, either=True)
    steps[100, 0] = 0.5 * limit
    assert not _leaves_track(steps, 0, 100, 103, either=True)  # no step at all: never


def test_off_the_takes_motion_and_the_surface_a_step_noise_makes_once_in_65000_is_a_step() -> None:
    """Steps against the neighbours of a marker with 0.5 mm noise (3-D, 1.61 sigma a coordinate:
    its own step and its neighbours' median step): the marker's 8 MADs put a step at about
    11 sigma; with the range off the take's motion and the surface (`either`), a step above 5 of
    the step's own sigma (8.05 sigma) is one, as a residual above 5 sigma is an outlier."""
    from lgi.solve.diagnose import NOISE_SIGMAS, _above_median, _leaves_track
    from lgi.solve.tracks import RELATIVE_STEP_NOISE

    sigma = 0.05
    rng = np.random.default_rng(5)
    steps = np.linalg.norm(rng.normal(0.0, RELATIVE_STEP_NOISE * sigma, (4000, 1, 3)), axis=2)
    assert 10.0 * sigma < _above_median(steps[:, 0], 8.0) < 12.0 * sigma
    bar = NOISE_SIGMAS * RELATIVE_STEP_NOISE * sigma
    steps[1000, 0], steps[1004, 0] = 1.1 * bar, 0.0  # a 0.44 cm step off, back in the noise
    assert not _leaves_track(steps, 0, 1000, 1003, either=True)  # by the MADs alone
    assert _leaves_track(steps, 0, 1000, 1003, either=True, noise=sigma)
    assert not _leaves_track(steps, 0, 1000, 1003, noise=sigma)  # both edges asked: never
    steps[1000, 0] = 0.9 * bar
    assert not _leaves_track(steps, 0, 1000, 1003, either=True, noise=sigma)
    # The noise's own steps: over 4,000 frames none reaches the bar (1.5e-5 a step).
    assert (np.delete(steps[:, 0], [1000, 1004]) < bar).all()


def test_off_the_takes_motion_a_range_a_frame_short_still_comes_back_and_a_blink_does_not() -> None:
    """Deviations from the take's motion (cm) of a marker at 0.5 mm noise: a 0.5 cm spike over
    frames 100-102 whose noisy residuals made a range of 100-101 only (frame 102 still off, 103
    back), against skin easing out and back over several frames."""
    from lgi.solve.diagnose import _off_the_take

    rng = np.random.default_rng(2)
    dev = np.abs(rng.normal(0.0, 0.05, (300, 1))) + 0.02
    dev[100:104, 0] = [0.57, 0.61, 0.37, 0.2]
    assert _off_the_take(dev, 0, 100, 102)  # the whole spike
    assert _off_the_take(dev, 0, 100, 101)  # a frame short: back at the frame beyond
    dev[98:100, 0] = [0.33, 0.42]  # eased in over two frames before the range as well
    assert not _off_the_take(dev, 0, 100, 101)
    dev[200:209, 0] = [0.2, 0.35, 0.45, 0.6, 0.62, 0.5, 0.42, 0.35, 0.2]  # a blink
    assert not _off_the_take(dev, 0, 203, 204)
