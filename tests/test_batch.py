"""`lgi.app.batch.solve_shots` on a `LocalCluster` of two worker processes, as a farm would run
it: every take's output equals `Model.solve` on the same frames (read back from the written
files), a corrupt take fails alone and is recorded in the manifest, a rerun skips the shots that
are done with the same input and retries the others, a model given as a shared path is loaded
once per worker; and `lgi batch` on the command line."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest

import lgi
from lgi.app import batch
from pipeline_files import lgi_cli, write_c3d

FPS = 30.0


@pytest.fixture(scope="module")
def client():  # type: ignore[no-untyped-def]
    """Two worker processes of one thread each: the cluster of every test in this module."""
    from dask.distributed import Client, LocalCluster

    with (
        LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address="127.0.0.1:0"
        ) as cluster,
        Client(cluster) as c,
    ):
        yield c


@pytest.fixture(scope="module")
def named_model(sample, sample_dataset):  # type: ignore[no-untyped-def]
    """The sample's model with its marker names and unit (takes are matched by label)."""
    return lgi.Model.build(
        sample_dataset, sample.markers_rest, jaw=None, marker_names=sample.marker_names, units="cm"
    )


@pytest.fixture(scope="module")
def shots(tmp_path_factory, sample):  # type: ignore[no-untyped-def]
    """Three good takes (a C3D in mm with its labels reversed, a C3D in cm, an array) from
    the sample's performance, a C3D that is garbage, and an array with an infinite marker."""
    folder = tmp_path_factory.mktemp("takes")
    perf = np.asarray(sample.performance, dtype=np.float64)
    names = list(sample.marker_names)
    order = np.arange(len(names))[::-1]
    write_c3d(folder / "sh010.c3d", perf[:12, order] * 10.0, [names[i] for i in order], FPS, "mm")
    write_c3d(folder / "sh020.c3d", perf[40:50], names, FPS, "cm")
    (folder / "sh030.c3d").write_bytes(np.random.default_rng(3).bytes(4000))
    broken = perf[60:66].copy()
    broken[2, 5] = np.inf
    return {
        "sh010": folder / "sh010.c3d",
        "sh020": folder / "sh020.c3d",
        "sh030": folder / "sh030.c3d",
        "sh040": perf[90:98],
        "sh050": broken,
    }


def direct(model: lgi.Model, take: Path | np.ndarray) -> lgi.SolveResult:
    """What `Model.solve` gives on the take, read as the batch reads it."""
    x = (
        take
        if isinstance(take, np.ndarray)
        else lgi.io.takes.read(take, model.marker_names, units="cm").frames
    )
    return model.solve(x, quiet=True, marker_noise=0.01)


@pytest.fixture(scope="module")
def first_run(client, named_model, shots, tmp_path_factory):  # type: ignore[no-untyped-def]
    out = tmp_path_factory.mktemp("batch")
    result = batch.solve_shots(
        named_model, shots, out, client=client, quiet=True, marker_noise=0.01
    )
    return out, result


def test_every_good_take_written_by_the_workers_equals_model_solve(first_run, named_model, shots):  # type: ignore[no-untyped-def]
    out, result = first_run
    for name in ("sh010", "sh020", "sh040"):
        shot = result.shots[name]
        assert shot.status == "done", shot.error
        written = lgi.io.result.read_result_npz(shot.output)
        ref = direct(named_model, shots[name])
        # The npz stores float32 vertices: the worker's solve, cast, equals ours bit for bit.
        assert np.array_equal(written.vertices, ref.vertices.astype(np.float32)), name
        assert np.array_equal(written.bundle_residuals, ref.bundle_residuals), name
        assert np.array_equal(written.missing, ref.missing), name
        assert shot.frames == ref.vertices.shape[0]
        assert Path(shot.output) == (out / f"{name}.npz").resolve()
    assert lgi.io.result.read_result_npz(result.shots["sh010"].output).fps == FPS


def test_a_corrupt_take_and_an_infinite_marker_fail_alone_and_are_in_the_manifest(  # type: ignore[no-untyped-def]
    first_run, shots, named_model
):
    out, result = first_run
    shots_files, model = shots, named_model
    assert sorted(result.failed) == ["sh030", "sh050"]
    manifest = json.loads((out / batch.MANIFEST).read_text())
    shots = manifest["shots"]
    assert sorted(shots) == ["sh010", "sh020", "sh030", "sh040", "sh050"]
    assert shots["sh030"]["status"] == "failed"
    assert "not a C3D file" in shots["sh030"]["error"]
    assert "sh030.c3d" in shots["sh030"]["error"]
    assert shots["sh050"]["status"] == "failed"
    assert shots["sh050"]["error"].startswith("InputError")
    assert "frame 2" in shots["sh050"]["error"], shots["sh050"]["error"]
    assert shots["sh030"]["output"] is None and not (out / "sh030.npz").exists()
    for name in ("sh010", "sh020", "sh040"):
        rec = shots[name]
        assert rec["status"] == "done" and rec["error"] is None
        assert rec["seconds"] > 0 and rec["frames"] > 0
    take = hashlib.sha256(Path(shots_files["sh010"]).read_bytes()).hexdigest()
    assert shots["sh010"]["input_hash"] == take
    assert manifest["model"]["markers"] == model.num_bundles
    assert manifest["model"]["sha256"] == hashlib.sha256(model.to_bytes()).hexdigest()


def test_a_rerun_skips_done_shots_and_retries_failed_and_changed_ones(  # type: ignore[no-untyped-def]
    client, named_model, shots, first_run, tmp_path, sample
):
    out0, _ = first_run
    out = tmp_path / "rerun"
    shutil.copytree(out0, out)
    # Outputs recorded with absolute paths: point the copied manifest at the copies.
    m = json.loads((out / batch.MANIFEST).read_text())
    for rec in m["shots"].values():
        if rec["output"]:
            rec["output"] = os.fspath(out / Path(rec["output"]).name)
    (out / batch.MANIFEST).write_text(json.dumps(m))
    stamps = {n: (out / f"{n}.npz").stat().st_mtime_ns for n in ("sh010", "sh020", "sh040")}
    fixed = dict(shots)
    fixed["sh030"] = shots["sh020"]  # the corrupt take replaced by a good one
    fixed["sh040"] = np.asarray(sample.performance[90:99], dtype=np.float64)  # one frame more
    result = batch.solve_shots(
        named_model, fixed, out, client=client, quiet=True, marker_noise=0.01
    )
    assert sorted(result.skipped) == ["sh010", "sh020"]
    for n in ("sh010", "sh020"):
        assert (out / f"{n}.npz").stat().st_mtime_ns == stamps[n]
    assert result.shots["sh030"].status == "done" and not result.shots["sh030"].skipped
    assert result.shots["sh040"].frames == 9 and not result.shots["sh040"].skipped
    assert result.failed == ["sh050"]
    ref = direct(named_model, fixed["sh040"])
    written = lgi.io.result.read_result_npz(out / "sh040.npz")
    assert np.array_equal(written.vertices, ref.vertices.astype(np.float32))
    # Other solve options are other settings: nothing is skipped.
    again = batch.solve_shots(
        named_model, {"sh010": shots["sh010"]}, out, client=client, quiet=True
    )
    assert again.skipped == [] and again.shots["sh010"].status == "done"


def test_a_model_on_a_shared_path_is_loaded_once_per_worker(client, named_model, shots, tmp_path):  # type: ignore[no-untyped-def]
    path = tmp_path / "actor.lgi"
    named_model.save(path)
    good = {n: shots[n] for n in ("sh010", "sh020", "sh040")}
    many = {f"{n}_{k}": t for n, t in good.items() for k in range(3)}
    result = batch.solve_shots(
        path, many, tmp_path / "out", client=client, quiet=True, marker_noise=0.01
    )
    assert result.failed == []
    loaded = client.run(lambda: len(batch._LOADED))
    assert sorted(loaded.values()) == [1, 1]  # nine shots, two workers, one load each
    for name, take in many.items():
        written = lgi.io.result.read_result_npz(result.shots[name].output)
        assert np.array_equal(
            written.vertices, direct(named_model, take).vertices.astype(np.float32)
        )


def test_the_model_is_scattered_once_to_both_workers_and_every_task_uses_that_copy(  # type: ignore[no-untyped-def]
    client, named_model, shots, tmp_path
):
    from dask.distributed import Client, Future

    class Recording(Client):
        """The module's cluster, recording what the batch sends through the client."""

        scattered: ClassVar[list[tuple[Any, dict[str, Any]]]] = []
        submitted: ClassVar[list[tuple[Any, ...]]] = []

        def scatter(self, data, **kwargs):  # type: ignore[no-untyped-def]
            future = super().scatter(data, **kwargs)
            self.scattered.append((future, kwargs))
            return future

        def submit(self, func, *args, **kwargs):  # type: ignore[no-untyped-def]
            self.submitted.append(args)
            return super().submit(func, *args, **kwargs)

    many = {f"shot{k}": shots["sh040"] for k in range(4)}
    with Recording(client.scheduler.address) as rec:
        # Both workers registered before the scatter, so that the broadcast reaches both (a
        # worker that joins later fetches the model from a peer: right, but not what this
        # test measures).
        rec.wait_for_workers(2)
        # The workers' transfer logs last as long as the module's cluster: this batch's only.
        rec.run(lambda dask_worker: dask_worker.transfer_incoming_log.clear())
        result = batch.solve_shots(named_model, many, tmp_path, client=rec, quiet=True)
        # Each assertion says what it saw: a rare failure here (seen twice in full runs, not
        # reproduced in 12 runs of this test alone) must say which step it was.
        models = [(f, kw) for f, kw in rec.scattered if f.type is lgi.Model]
        assert len(models) == 1 and models[0][1].get("broadcast") is True, rec.scattered
        model_future = models[0][0]
        assert isinstance(model_future, Future)
        # Both workers held the model from the scatter on: none fetched it from a peer for
        # a task (dask logs every transfer between workers).
        fetched = rec.run(
            lambda dask_worker: [k for t in dask_worker.transfer_incoming_log for k in t["keys"]]
        )
        assert len(fetched) == 2, fetched
        assert all(model_future.key not in keys for keys in fetched.values()), (
            model_future.key,
            fetched,
        )
        assert len(rec.submitted) == 4, rec.submitted
        assert all(args[0] is model_future for args in rec.submitted), rec.submitted
    assert result.failed == [], result.failed


def test_usd_and_obj_outputs_hold_the_solve_and_a_rerun_skips_them(  # type: ignore[no-untyped-def]
    client, named_model, shots, tmp_path
):
    from pxr import Usd, UsdGeom

    take = {"sh020": shots["sh020"]}
    ref = direct(named_model, shots["sh020"])
    usd = batch.solve_shots(
        named_model,
        take,
        tmp_path / "usd",
        client=client,
        output="usd",
        quiet=True,
        marker_noise=0.01,
    )
    assert usd.shots["sh020"].output == os.fspath((tmp_path / "usd" / "sh020.usdc").resolve())
    stage = Usd.Stage.Open(usd.shots["sh020"].output)
    assert stage.GetTimeCodesPerSecond() == FPS
    points = UsdGeom.Mesh(stage.GetPrimAtPath("/Face/Mesh")).GetPointsAttr()
    times = points.GetTimeSamples()
    assert len(times) == ref.vertices.shape[0]
    for f, t in enumerate(times):
        got = np.array(points.Get(t))
        assert np.array_equal(got, ref.vertices[f].astype(np.float32))

    def to_obj() -> batch.BatchResult:
        return batch.solve_shots(
            named_model,
            take,
            tmp_path / "obj",
            client=client,
            output="obj",
            quiet=True,
            marker_noise=0.01,
        )

    obj = to_obj()
    files = sorted((tmp_path / "obj").glob("sh020.*.obj"))
    assert len(files) == ref.vertices.shape[0]
    first = np.array(
        [line.split()[1:] for line in files[0].read_text().splitlines() if line.startswith("v ")],
        dtype=np.float64,
    )
    np.testing.assert_allclose(first, ref.vertices[0], rtol=0, atol=1e-6 * named_model.diagonal)
    assert obj.shots["sh020"].output.endswith("sh020.NNNN.obj")
    again = to_obj()
    assert again.skipped == ["sh020"]


def test_progress_shows_shots_as_they_finish_unless_quiet(
    client, named_model, shots, tmp_path, capsys
):  # type: ignore[no-untyped-def]
    take = {"sh040": shots["sh040"]}
    batch.solve_shots(named_model, take, tmp_path / "a", client=client, quiet=True)
    assert "lgi batch" not in capsys.readouterr().err
    batch.solve_shots(named_model, take, tmp_path / "b", client=client)
    assert "lgi batch: 100%" in capsys.readouterr().err


def test_a_scheduler_address_runs_the_batch_on_that_cluster(client, named_model, shots, tmp_path):  # type: ignore[no-untyped-def]
    from dask.distributed import get_task_stream

    with get_task_stream(client) as stream:
        result = batch.solve_shots(
            named_model,
            {"sh040": shots["sh040"]},
            tmp_path,
            client=client.scheduler.address,
            quiet=True,
            marker_noise=0.01,
        )
    # The task ran on this module's cluster (no cluster of its own was started).
    assert any(str(t["key"]).startswith("lgi-shot-sh040-") for t in stream.data)
    assert result.failed == []
    written = lgi.io.result.read_result_npz(result.shots["sh040"].output)
    ref = direct(named_model, shots["sh040"])
    assert np.array_equal(written.vertices, ref.vertices.astype(np.float32))


def _one_shot(client, model, take, out, **options):  # type: ignore[no-untyped-def]
    """`take` solved as shot sh040 by the batch with `options`: what it wrote (it must be done)."""
    shot = batch.solve_shots(
        model, {"sh040": take}, out, client=client, quiet=True, **options
    ).shots["sh040"]
    assert shot.status == "done", shot.error
    return lgi.io.result.read_result_npz(shot.output)


def test_a_batch_detail_weight_auto_is_the_takes_own_estimate(client, named_model, shots, tmp_path):  # type: ignore[no-untyped-def]
    take = shots["sh040"]
    written = _one_shot(
        client, named_model, take, tmp_path / "o", marker_noise=0.01, detail_weight="auto"
    )
    w = lgi.estimate_detail_weight(take, named_model, marker_noise=0.01)
    ref = named_model.solve(take, quiet=True, marker_noise=0.01, detail_weight=w)
    assert np.array_equal(written.vertices, ref.vertices.astype(np.float32))


def test_a_batch_with_local_fits_writes_what_model_solve_gives_and_says_so(
    client, named_model, shots, tmp_path
):  # type: ignore[no-untyped-def]
    take = shots["sh040"]
    written = _one_shot(
        client, named_model, take, tmp_path / "o", marker_noise=0.01, local_fits=True
    )
    ref = named_model.solve(take, quiet=True, marker_noise=0.01, local_fits=True)
    assert np.array_equal(written.vertices, ref.vertices.astype(np.float32))
    assert written.settings is not None and written.settings.local_fits


def test_a_batch_with_the_unbounded_fit_writes_what_model_solve_gives_and_records_it(
    client, named_model, shots, tmp_path
):  # type: ignore[no-untyped-def]
    take = shots["sh040"]
    written = _one_shot(
        client, named_model, take, tmp_path / "o", marker_noise=0.01, fit="unbounded"
    )
    ref = named_model.solve(take, quiet=True, marker_noise=0.01, fit="unbounded")
    assert np.array_equal(written.vertices, ref.vertices.astype(np.float32))
    assert written.settings is not None and written.settings.unbounded_fit


def test_a_batch_with_the_unbounded_fit_auto_records_the_takes_own_choice(
    client, named_model, shots, tmp_path
):  # type: ignore[no-untyped-def]
    take = shots["sh040"]
    written = _one_shot(client, named_model, take, tmp_path / "o", marker_noise=0.01, fit="auto")
    fit = lgi.estimate_unbounded_fit(take, named_model, marker_noise=0.01).fit
    ref = named_model.solve(take, quiet=True, marker_noise=0.01, fit=fit)
    assert np.array_equal(written.vertices, ref.vertices.astype(np.float32))
    assert written.settings is not None and written.settings.unbounded_fit is (fit is not None)


def test_a_batch_with_the_take_prior_writes_what_model_solve_gives_and_records_it(
    client, named_model, shots, tmp_path
):  # type: ignore[no-untyped-def]
    take = shots["sh040"]
    written = _one_shot(
        client,
        named_model,
        take,
        tmp_path / "o",
        marker_noise=0.01,
        fit="unbounded",
        take_prior=True,
    )
    prior = lgi.estimate_take_prior(named_model, take, 0.01)
    ref = named_model.solve(take, quiet=True, marker_noise=0.01, fit="unbounded", take_prior=prior)
    assert np.array_equal(written.vertices, ref.vertices.astype(np.float32))
    assert written.settings is not None and written.settings.take_prior


def test_a_batch_with_local_fits_auto_records_the_takes_own_choice(
    client, named_model, shots, tmp_path
):  # type: ignore[no-untyped-def]
    take = shots["sh040"]
    written = _one_shot(
        client, named_model, take, tmp_path / "o", marker_noise=0.01, local_fits="auto"
    )
    use = lgi.estimate_local_fits(take, named_model, marker_noise=0.01).use
    ref = named_model.solve(take, quiet=True, marker_noise=0.01, local_fits=use)
    assert np.array_equal(written.vertices, ref.vertices.astype(np.float32))
    assert written.settings is not None and written.settings.local_fits is use


def test_a_batch_with_denoise_solves_the_denoised_take_and_records_it(
    client, named_model, shots, tmp_path
):  # type: ignore[no-untyped-def]
    take = shots["sh040"]
    written = _one_shot(client, named_model, take, tmp_path / "o", marker_noise=0.01, denoise=True)
    den = lgi.denoise_take(take, 0.01)
    # Faults and gaps are read at the given markers' noise (`fault_noise`), as the plan says.
    ref = named_model.solve(den.frames, quiet=True, marker_noise=den.marker_noise, fault_noise=0.01)
    assert np.array_equal(written.vertices, ref.vertices.astype(np.float32))
    assert written.settings is not None and written.settings.denoised_from == 0.01
    assert written.settings.marker_noise == den.marker_noise < 0.01
    assert written.settings.denoised_rank == den.rank
    # The residuals written are the given markers' distances from where the solve put them:
    # that surface's markers less the pulls that moved it to markers beyond their noise.
    on_surface = named_model.bundle_positions(np.asarray(written.vertices, dtype=np.float64))
    put = on_surface - (0.0 if ref.marker_pulls is None else ref.marker_pulls)
    expected = np.nan_to_num(np.linalg.norm(np.asarray(take) - put, axis=2))
    np.testing.assert_allclose(written.bundle_residuals, expected, atol=1e-5)


def test_a_batch_recommended_solves_the_plan_lgi_solve_reads_and_records_it(
    client, named_model, shots, tmp_path
):  # type: ignore[no-untyped-def]
    from lgi.plan.choices import plan_solve

    take = shots["sh040"]
    written = _one_shot(client, named_model, take, tmp_path / "o", recommended=True)
    plan = plan_solve(np.asarray(take, dtype=np.float64), named_model, recommended=True)
    ref = named_model.solve(plan.frames, quiet=True, options=plan.options)
    assert np.array_equal(written.vertices, ref.vertices.astype(np.float32))
    assert written.settings is not None
    assert written.settings.marker_noise == plan.marker_noise
    assert written.settings.denoised_from == plan.given_noise
    assert written.settings.local_fits == plan.local_fits


def test_solve_shots_refuses_bad_arguments_before_starting_anything(named_model, tmp_path):  # type: ignore[no-untyped-def]
    take = np.zeros((2, named_model.num_bundles, 3))
    cases = [
        ({"takes": [take]}, "expected a mapping"),
        ({"takes": {"a/b": take}}, "shot name"),
        ({"output": "fbx"}, "output 'fbx'"),
        ({"workers": 0}, "workers"),
        ({"threads": 1.5}, "threads"),
        ({"smoothing": 3}, "unknown solve options"),
        ({"marker_noise": "loud"}, "marker_noise"),
        ({"detail_weight": 1.5}, "detail_weight: expected a number in"),
        ({"detail_weight": "some"}, "detail_weight: expected a number in"),
        ({"local_fits": True}, "local_fits needs marker_noise"),
        (
            {"local_fits": 1, "marker_noise": 0.01},
            "local_fits must be True, False, .unbounded. or .auto.",
        ),
        ({"fit": "free"}, "fit must be True, False, None, .unbounded. or .auto."),
        ({"take_prior": "yes"}, "take_prior must be True, False or .auto."),
        ({"denoise": "yes", "marker_noise": 0.01}, "denoise must be True or False"),
        ({"denoise": True}, "denoise needs marker_noise above 0"),
        ({"recommended": "yes"}, "recommended must be True or False"),
        ({"denoise": True, "marker_noise": 0.0}, "denoise needs marker_noise above 0"),
        ({"model": tmp_path / "none.lgi"}, "no such model file"),
        ({"client": 3}, "client: expected"),
        ({"client": "tcp://127.0.0.1:8786", "workers": 2}, "workers sizes the embedded"),
    ]
    inside = tmp_path / "o" / "a.npz"
    inside.parent.mkdir()
    np.savez(inside, frames=take)
    cases.append(({"takes": {"a": inside}}, "the file its output would replace"))
    for kwargs, message in cases:
        args = {"model": named_model, "takes": {"a": take}, "out_dir": tmp_path / "o", **kwargs}
        with pytest.raises(lgi.InputError, match=message):
            batch.solve_shots(quiet=True, **args)


def test_lgi_batch_solves_takes_on_its_own_cluster_and_fails_with_exit_2_on_a_bad_take(  # type: ignore[no-untyped-def]
    named_model, shots, tmp_path
):
    model = tmp_path / "actor.lgi"
    named_model.save(model)
    out = tmp_path / "out"
    r = lgi_cli("batch", model, shots["sh010"], shots["sh020"], "-o", out, "--workers", "2", "-q")
    assert r.returncode == 0, r.stderr
    assert "2 of 2 shots done" in r.stdout
    written = lgi.io.result.read_result_npz(out / "sh020.npz")
    ref = named_model.solve(
        lgi.io.takes.read(shots["sh020"], named_model.marker_names, units="cm").frames, quiet=True
    )
    assert np.array_equal(written.vertices, ref.vertices.astype(np.float32))
    r = lgi_cli("batch", model, shots["sh010"], shots["sh030"], "-o", out, "-q", "--workers", "1")
    assert r.returncode == 2
    assert "lgi: error: 1 of 2 shots failed" in r.stderr and "sh030" in r.stderr
    assert "1 skipped" in r.stdout


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--workers", "0"], "--workers"),
        (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "--workers sizes"),
        (["--format", "fbx"], "--format"),
        (["DUP"], "two takes named 'sh010'"),
        (["--marker-noise", "loud"], "--marker-noise"),
        (["--detail-weight", "1.5"], "--detail-weight"),
        (["--local-fits"], "--local-fits needs --marker-noise"),
    ],
)
def test_lgi_batch_mistakes_are_lgi_error_exit_2(named_model, shots, tmp_path, extra, message):  # type: ignore[no-untyped-def]
    model = tmp_path / "actor.lgi"
    named_model.save(model)
    dup = tmp_path / "again" / "sh010.c3d"
    dup.parent.mkdir()
    shutil.copy(shots["sh010"], dup)
    extra = [os.fspath(dup) if e == "DUP" else e for e in extra]
    r = lgi_cli("batch", model, shots["sh010"], *extra, "-o", tmp_path / "out", "-q")
    assert r.returncode == 2
    assert "lgi: error:" in r.stderr and message in r.stderr, r.stderr
    assert not (tmp_path / "out" / "sh010.npz").exists()
