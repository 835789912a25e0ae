"""`--recommended` (`lgi.plan.choices.plan_solve(recommended=True)`): every solve option read from
the take, checked against the readings it is made of, called one at a time, and `lgi solve
--recommended` end to end against `Model.solve` of the plan."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

import lgi
from lgi.plan import choices
from lgi.plan.choices import plan_solve


def test_recommended_is_the_readings_it_is_made_of_called_one_after_another(
    sample, noise_aware_sample
) -> None:  # type: ignore[no-untyped-def]
    model, _ = noise_aware_sample
    x = np.asarray(sample.performance, dtype=np.float64)
    said: list[str] = []
    plan = plan_solve(x, model, recommended=True, say=said.append)
    # The noise as `--marker-noise auto` reads it, the take denoised with it ...
    sigma = lgi.estimate_marker_noise(x, model)
    assert plan.given_noise == sigma > 0
    den = lgi.denoise_take(x, sigma)
    assert plan.denoised is not None and np.array_equal(plan.frames, den.frames, equal_nan=True)
    assert plan.marker_noise == den.marker_noise < sigma
    # ... and each choice read on the denoised take, as the options given one by one read it.
    local, free = choices.fits_choice(
        "auto", "auto", den.frames, model, den.marker_noise, "auto", lambda _: None, "auto"
    )
    assert (plan.local_fits, plan.unbounded_fit) == (local, free)
    if not local:
        w = lgi.estimate_detail_weight(
            den.frames, model, marker_noise=den.marker_noise, fit=plan.fit
        )
        assert plan.detail_weight == w
    assert said[0] == choices.RECOMMENDED
    assert f"marker noise read from the take: {sigma:.4g}" in said
    assert any(line.startswith("denoised the take:") for line in said)
    assert any(line.startswith("local fits ") for line in said)
    assert any(line.startswith("take prior ") for line in said)


@pytest.mark.parametrize("local", [False, True, "unbounded"])
def test_recommended_reads_the_detail_weight_only_where_no_local_fits_are_used(
    monkeypatch: pytest.MonkeyPatch, sample, noise_aware_sample, local: bool | str
) -> None:  # type: ignore[no-untyped-def]
    model, sigma = noise_aware_sample
    x = np.asarray(sample.performance, dtype=np.float64)[:20]
    read: list[Any] = []

    def fits(spec, unbounded, frames, m, s, jaw, say, prior=False, readings=None):  # type: ignore[no-untyped-def]
        assert (spec, unbounded, prior) == ("auto", "auto", "auto")
        return local, local == "unbounded"

    def weight(spec, frames, m, s, jaw, fit=None):  # type: ignore[no-untyped-def]
        read.append(spec)
        return 0.5

    monkeypatch.setattr(choices, "fits_choice", fits)
    monkeypatch.setattr(choices, "detail_weight", weight)
    monkeypatch.setattr(choices, "take_prior_choice", lambda *a, **k: None)
    plan = plan_solve(x, model, marker_noise=sigma, recommended=True)
    assert plan.local_fits == local
    assert read == ([] if local else ["auto"])
    assert plan.detail_weight == (None if local else 0.5)
    # A detail weight given is kept, local fits or not.
    read.clear()
    given = plan_solve(x, model, marker_noise=sigma, detail_weight="0.25", recommended=True)
    assert read == [0.25] and given.detail_weight == 0.5


def test_recommended_keeps_the_options_given_and_leaves_noise_free_markers_as_given(
    sample, noise_aware_sample
) -> None:  # type: ignore[no-untyped-def]
    model, _ = noise_aware_sample
    x = np.asarray(sample.performance, dtype=np.float64)[:30]
    said: list[str] = []
    plan = plan_solve(
        x, model, marker_noise=0.0, fit="unbounded", recommended=True, say=said.append
    )
    assert plan.denoised is None and plan.given_noise == plan.marker_noise == 0.0
    assert "not denoised: the markers' noise is 0 (nothing to remove)" in said
    assert plan.unbounded_fit and plan.fit == "unbounded"
    assert plan.frames is x
    assert not any(line.startswith("marker noise read") for line in said)
    # --marker-noise none (every marker interpolated as given): nothing to denoise, and local
    # fits (which fit the noise-aware targets) are not read; said, not an error.
    said.clear()
    exact = plan_solve(x, model, marker_noise="none", recommended=True, say=said.append)
    assert exact.marker_noise is None and exact.denoised is None and exact.local_fits is False
    assert "not denoised: no marker noise (nothing to remove)" in said
    assert any(line.startswith("local fits not read: no marker noise") for line in said)
    # Without --recommended, --denoise asked for noise-free markers is an error, as before.
    with pytest.raises(lgi.InputError, match="denoise needs marker_noise above 0"):
        plan_solve(x, model, marker_noise=0.0, denoise=True)


def test_lgi_solve_recommended_writes_model_solve_of_its_plan_and_records_it(
    sample, noise_aware_sample, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:  # type: ignore[no-untyped-def]
    from lgi.app.cli import main
    from lgi.io.result import read_result_npz

    model, _ = noise_aware_sample
    model_path = tmp_path / "m.lgi"
    model.save(model_path)
    markers = np.asarray(sample.performance, dtype=np.float64)[:60]
    take = tmp_path / "take.npz"
    np.savez(take, markers=markers, names=np.array(model.marker_names), fps=30.0)
    out = tmp_path / "out.npz"
    assert main(["solve", str(model_path), str(take), "-o", str(out), "--recommended"]) == 0
    said = capsys.readouterr().err
    assert choices.RECOMMENDED in said and "denoised the take:" in said, said
    plan = plan_solve(markers, model, recommended=True)
    ref = model.solve(plan.frames, quiet=True, options=plan.options)
    r = read_result_npz(out)
    np.testing.assert_array_equal(r.vertices, ref.vertices.astype(np.float32))
    assert r.settings is not None
    assert r.settings.denoised_from == pytest.approx(plan.given_noise)
    assert r.settings.marker_noise == pytest.approx(plan.marker_noise)
    assert r.settings.local_fits == plan.local_fits
    assert r.settings.unbounded_fit == plan.unbounded_fit


def test_plan_solve_names_an_option_it_does_not_know_in_our_words(noise_aware_sample) -> None:  # type: ignore[no-untyped-def]
    model, _ = noise_aware_sample
    x = np.zeros((2, model.num_bundles, 3))
    with pytest.raises(lgi.InputError, match=r"plan_solve: unknown solve options \['noise'\]"):
        plan_solve(x, model, noise=0.1)
    with pytest.raises(lgi.InputError, match="as options= or as keywords"):
        plan_solve(x, model, lgi.SolveOptions(), marker_noise=0.1)
