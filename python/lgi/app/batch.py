"""Many shots at once on `dask.distributed`: each take is one task, the model is shipped once
per worker (scattered with `broadcast=True`, or loaded by each worker from a shared path), the
workers write their outputs with the pipeline's writers, and a JSON manifest in the output
folder records every shot, so a rerun skips what is done and retries what failed. Without a
client the batch runs on a `LocalCluster` of worker processes sized to the machine; a scheduler
address or a `Client` runs the same code on a real cluster (docs/scale.md)."""

from __future__ import annotations

import hashlib
import json
import os
import re
import time
from collections import OrderedDict
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lgi.app.pipeline import check_take_scale, plan_take, read_take, solve_take
from lgi.app.write import write_solved
from lgi.errors import InputError
from lgi.io.atomic import atomic_path, writable_folder
from lgi.io.topology import topology
from lgi.solve.model import Model
from lgi.solve.options import SolveOptions

__all__ = [
    "MANIFEST",
    "OUTPUT_FORMATS",
    "BatchResult",
    "Shot",
    "default_workers",
    "solve_shots",
]

MANIFEST = "manifest.json"
"""The manifest's file name in the output folder."""

MANIFEST_VERSION = 1

OUTPUT_FORMATS = {"npz": ".npz", "usd": ".usdc", "obj": ".obj"}
"""`output=` of `solve_shots` and the suffix of each shot's file (`obj`: `NAME.NNNN.obj`)."""

_SHOT_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")

# What a worker process keeps between its tasks: the models it loaded from a shared path, by
# (path, content hash), so each worker reads a model file once, not once per shot; the two
# used last (a long-lived worker serving many actors does not keep every model).
_LOADED: OrderedDict[tuple[str, str], Model] = OrderedDict()
_KEEP_LOADED = 2


@dataclass(frozen=True)
class Shot:
    """One shot's record in the manifest."""

    name: str
    status: str
    """"done" or "failed"."""
    frames: int | None
    """Frames solved (None when the shot failed before its take was read)."""
    seconds: float | None
    """Wall time of the task on its worker (reading, solving, writing)."""
    output: str | None
    """The file written (`NAME.NNNN.obj` for an OBJ sequence), None when failed."""
    error: str | None
    """Why the shot failed (`ExceptionClass: message`), None when done."""
    input_hash: str | None
    """sha256 of the take's content (a file's bytes, or an array's dtype, shape and bytes)."""
    settings_hash: str
    """sha256 of the model's bytes, the solve options, the output format and lgi's version."""
    skipped: bool = field(default=False, compare=False)
    """Done in an earlier run with the same input and settings, not solved again (not saved)."""


@dataclass(frozen=True)
class BatchResult:
    """What `solve_shots` did: every shot of this batch, and where the manifest is."""

    shots: dict[str, Shot]
    manifest: Path

    @property
    def failed(self) -> list[str]:
        return [n for n, s in self.shots.items() if s.status != "done"]

    @property
    def skipped(self) -> list[str]:
        return [n for n, s in self.shots.items() if s.skipped]


def default_workers() -> int:
    """Worker processes of the embedded `LocalCluster`: one per two cores (each solving with
    two threads; docs/scale.md measures one against two), at least one."""
    return max(1, (os.cpu_count() or 1) // 2)


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _sha256_array(a: np.ndarray) -> str:
    h = hashlib.sha256(f"{a.dtype.str}{a.shape}".encode())
    h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _recorded(options: SolveOptions) -> str:
    """The options given as canonical JSON (hashed into the settings); a value a manifest
    cannot record (a `TakePrior`: read one per take with take_prior=True) is an InputError."""
    try:
        return json.dumps(options.record(), sort_keys=True, allow_nan=False)
    except (TypeError, ValueError):
        raise InputError(
            f"solve_shots: solve options must be plain values, got {options.record()!r}"
        ) from None


def _take_inputs(
    takes_in: Mapping[str, Any], num_bundles: int
) -> dict[str, tuple[str | np.ndarray, str | None, str | None]]:
    """Per shot: the take (a path string or a float64 array), its content hash, and why it
    cannot be solved (None when it can: a missing file or a wrong array fails its shot alone)."""
    if not isinstance(takes_in, Mapping):
        raise InputError(
            f"takes: expected a mapping of shot names to take files or (F, B, 3) arrays, "
            f"got {type(takes_in).__name__}"
        )
    out: dict[str, tuple[str | np.ndarray, str | None, str | None]] = {}
    for name, take in takes_in.items():
        if not isinstance(name, str) or not _SHOT_NAME.fullmatch(name) or name == MANIFEST:
            raise InputError(
                f"takes: shot name {name!r} must be letters, digits, '.', '_' or '-' (it names "
                "the shot's output file)"
            )
        if isinstance(take, (str, os.PathLike)):
            # Absolute: a worker's working folder need not be the caller's.
            p = Path(take).absolute()
            if not p.is_file():
                out[name] = (os.fspath(p), None, f"InputError: {p}: no such take file")
            else:
                out[name] = (os.fspath(p), _sha256_file(p), None)
            continue
        try:
            arr = np.asarray(take, dtype=np.float64)
        except (TypeError, ValueError) as e:
            out[name] = (
                np.zeros((0, num_bundles, 3)),
                None,
                f"InputError: not a number array: {e}",
            )
            continue
        error = None
        if arr.ndim != 3 or arr.shape[1:] != (num_bundles, 3):
            error = f"InputError: expected frames (F, {num_bundles}, 3), got shape {arr.shape}"
        out[name] = (arr, _sha256_array(arr), error)
    return out


def _read_manifest(path: Path) -> dict[str, dict[str, Any]]:
    """The shots of an earlier run's manifest (none when there is none)."""
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        shots = data["shots"]
        if data.get("version") != MANIFEST_VERSION or not isinstance(shots, dict):
            raise ValueError("unknown layout")
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as e:
        raise InputError(
            f"{path}: not a manifest lgi can read ({e}); move it away to start the batch afresh"
        ) from None
    return shots


def _write_manifest(
    path: Path, model_info: dict[str, Any], shots: dict[str, dict[str, Any]]
) -> None:
    """Writes the manifest atomically (a crash mid-batch leaves the previous one whole)."""
    data = {"version": MANIFEST_VERSION, "model": model_info, "shots": shots}
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n", encoding="utf-8")


def _record(shot: Shot) -> dict[str, Any]:
    d = asdict(shot)
    del d["name"], d["skipped"]
    return d


def _worker_model(model: Model | tuple[str, str]) -> Model:
    """The task's model: scattered (already unpickled on this worker), or loaded once per
    worker process from a shared path."""
    if isinstance(model, Model):
        return model
    if model not in _LOADED:
        _LOADED[model] = Model.load(model[0])
        while len(_LOADED) > _KEEP_LOADED:
            _LOADED.popitem(last=False)
    _LOADED.move_to_end(model)
    return _LOADED[model]


def solve_shot(
    model: Model | tuple[str, str],
    take: str | np.ndarray,
    dest: str,
    *,
    kind: str,
    options: SolveOptions,
    allow_missing: bool = False,
    take_units: str | None = None,
    fps: float | None = None,
    threads: int | None = None,
) -> dict[str, Any]:
    """One task: read the take, solve it (its marker faults repaired with `options.repair`, as
    `lgi solve` repairs them), write it to `dest`; on a worker. Returns
    `{"status", "frames", "seconds", "output", "error"}`; it never raises for a bad shot (the
    error is the record's), so one shot's failure stops no other."""
    t0 = time.perf_counter()
    frames: int | None = None
    try:
        import lgi

        if threads is not None:
            lgi.set_num_threads(threads)
        m = _worker_model(model)
        if isinstance(take, str):
            t = read_take(take, m, take_units=take_units, allow_missing=allow_missing)
            x, rate, start = t.frames, fps if fps is not None else t.fps, t.first_frame
            check_take_scale(t, t.frames, m, stated=take_units is not None)
        else:
            x, rate, start = take, fps, 0
        frames = int(x.shape[0])
        # What is solved and how, each option as given or read from the take, as `lgi solve`
        # plans it (`lgi.app.pipeline.plan_take`); the residuals written stay the given markers'.
        planned = plan_take(x, m, options)
        if kind == "usd" and rate is None:
            raise InputError("the take has no frame rate; a USD point cache needs fps=")
        planned, res, _ = solve_take(planned, m, options, start=start)
        written = write_solved(
            kind,
            Path(dest),
            topology(m.dataset),
            res,
            m,
            fps=rate,
            start=start,
            quiet=True,
            settings=planned.settings,
            residuals=planned.residuals(res),
        )
        return {
            "status": "done",
            "frames": frames,
            "seconds": time.perf_counter() - t0,
            "output": os.fspath(written),
            "error": None,
        }
    except Exception as e:  # the shot's failure is its record, never the batch's
        return {
            "status": "failed",
            "frames": frames,
            "seconds": time.perf_counter() - t0,
            "output": None,
            "error": f"{type(e).__name__}: {e}",
        }


@contextmanager
def _connect(
    client: Any, workers: int | None, threads: int | None, shots: int
) -> Iterator[tuple[Any, int | None]]:
    """The client to run on and the threads each task solves with: the given `Client`, one
    connected to a scheduler address, or an embedded `LocalCluster` (closed afterwards) of at
    most one worker per shot to solve."""
    from dask.distributed import Client, LocalCluster

    if client is None:
        n = min(shots, default_workers() if workers is None else workers)
        per = threads if threads is not None else max(1, (os.cpu_count() or 1) // n)
        with (
            LocalCluster(
                n_workers=n,
                threads_per_worker=1,
                processes=True,
                # A free port on this machine only: the default 8787 may be taken by another
                # cluster (a warning) and need not be open to the network.
                dashboard_address="127.0.0.1:0",
            ) as cluster,
            Client(cluster) as c,
        ):
            yield c, per
        return
    if isinstance(client, str):
        try:
            c = Client(client, timeout="30s")
        except (OSError, TimeoutError, ValueError) as e:
            raise InputError(f"scheduler {client}: cannot connect ({e})") from None
        with c:
            yield c, threads
        return
    yield client, threads


def _check_client(client: Any, workers: int | None) -> None:
    """`client` is None, an address or a `Client`; `workers` goes only with None."""
    from dask.distributed import Client

    if client is not None and not isinstance(client, (str, Client)):
        raise InputError(
            f"client: expected a dask.distributed.Client, a scheduler address or None, got "
            f"{type(client).__name__}"
        )
    if client is not None and workers is not None:
        raise InputError(
            "workers sizes the embedded cluster; a scheduler's workers are its own (start "
            "them with `dask worker`)"
        )


def solve_shots(
    model: Model | str | os.PathLike[str],
    takes: Mapping[str, str | os.PathLike[str] | np.ndarray],
    out_dir: str | os.PathLike[str],
    *,
    client: Any = None,
    workers: int | None = None,
    threads: int | None = None,
    output: str = "npz",
    fps: float | None = None,
    allow_missing: bool = False,
    take_units: str | None = None,
    quiet: bool = False,
    options: SolveOptions | None = None,
    **solve_options: Any,
) -> BatchResult:
    """Solves every take of `takes` (shot name -> a take file `lgi.io.takes.read` reads, or an
    (F, B, 3) array in the model's units) with `model` into `out_dir/NAME.npz` (`output`:
    "npz", "usd" for `NAME.usdc` point caches, "obj" for `NAME.NNNN.obj` sequences), one
    `dask.distributed` task per shot, and records each shot in `out_dir/manifest.json`.

    `client`: None runs an embedded `LocalCluster` of `workers` processes (default
    `default_workers()`); a scheduler address (`"tcp://host:8786"`) or a `Client` runs on that
    cluster (its workers need lgi installed and, for take files and a model path, the same
    paths). `model` is a `Model` (scattered once to every worker) or the path of a model file
    the workers can read (each loads it once). `threads`: each task's solve threads
    (`lgi.set_num_threads`); default: the cores shared among the local workers, or the
    worker's own default on a given cluster.

    `options` (a `SolveOptions`, or its fields as keywords `solve_options`) are planned per
    take as `lgi solve` plans them (`lgi.plan_solve`: 'auto' values read from each take,
    `recommended` every default; `repair`, the default, repairs each shot's marker faults as
    `lgi solve` does: `lgi.app.pipeline.solve_take`); `fps` is the
    output's frame rate when the take has none (arrays); `allow_missing` and `take_units` are
    `lgi.io.takes.read`'s.

    A shot whose take cannot be read or solved fails alone: its error is in the manifest and
    the others go on. A rerun into the same folder skips shots that are done with the same
    take content and settings (model bytes, options, format) and retries the others. Progress
    (a bar of shots) shows as shots finish; `quiet` hides it."""
    from tqdm import tqdm

    if output not in OUTPUT_FORMATS:
        raise InputError(f"output {output!r}: expected one of {', '.join(OUTPUT_FORMATS)}")
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int) or workers < 1
    ):
        raise InputError(f"workers must be a whole number >= 1, got {workers!r}")
    if threads is not None and (
        isinstance(threads, bool) or not isinstance(threads, int) or threads < 1
    ):
        raise InputError(f"threads must be a whole number >= 1, got {threads!r}")
    if fps is not None and not (isinstance(fps, (int, float)) and np.isfinite(fps) and fps > 0):
        raise InputError(f"fps must be a positive number, got {fps!r}")
    _check_client(client, workers)
    options = SolveOptions.given(options, solve_options, "solve_shots")
    options_json = _recorded(options)
    if isinstance(model, Model):
        the_model: Model = model
        model_bytes = model.to_bytes()
        model_hash = hashlib.sha256(model_bytes).hexdigest()
        shared: tuple[str, str] | None = None
    elif isinstance(model, (str, os.PathLike)):
        p = Path(model)
        if not p.is_file():
            raise InputError(f"model {p}: no such model file")
        model_hash = _sha256_file(p)
        shared = (os.fspath(p.resolve()), model_hash)
        the_model = Model.load(p)
    else:
        raise InputError(
            f"model: expected an lgi.Model or a model file path, got {type(model).__name__}"
        )
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError(f"out_dir {out}: is a file, expected a folder")
    inputs = _take_inputs(takes, the_model.num_bundles)
    for name, (take, _, _) in inputs.items():
        dest = out.absolute() / f"{name}{OUTPUT_FORMATS[output]}"
        if isinstance(take, str) and Path(take).resolve() == dest.resolve():
            raise InputError(
                f"takes: {name}'s take {take} is the file its output would replace; choose "
                "another out_dir (nothing given is modified)"
            )
    writable_folder(out, "out_dir", MANIFEST)  # before any shot is solved, not after
    import lgi

    # A batch without repair is another setting: `repair` is among the options recorded.
    settings_hash = hashlib.sha256(
        (
            f"{model_hash}\n{options_json}\n{output}\n{fps}\n{allow_missing}\n{take_units}\n"
            f"{lgi.__version__}"
        ).encode()
    ).hexdigest()
    manifest = out / MANIFEST
    records = _read_manifest(manifest)
    model_info = {
        "sha256": model_hash,
        "markers": the_model.num_bundles,
        "vertices": the_model.num_vertices,
        "options": json.loads(options_json),
        "output": output,
    }
    result: dict[str, Shot] = {}
    todo: list[str] = []
    for name, (_, digest, error) in inputs.items():
        old = records.get(name)
        if (
            old is not None
            and old.get("status") == "done"
            and digest is not None
            and old.get("input_hash") == digest
            and old.get("settings_hash") == settings_hash
            and old.get("output")
            and _exists(old["output"])
        ):
            result[name] = _shot_of(name, old, skipped=True)
        elif error is not None:
            result[name] = Shot(name, "failed", None, None, None, error, digest, settings_hash)
            records[name] = _record(result[name])
        else:
            todo.append(name)
    _write_manifest(manifest, model_info, records)
    if not todo:
        return BatchResult(shots=result, manifest=manifest)
    with (
        _connect(client, workers, threads, len(todo)) as (c, per_task),
        tqdm(total=len(todo), desc="lgi batch", unit="shot", disable=quiet) as bar,
    ):
        from dask.distributed import as_completed

        # Once per worker: the model's bytes to every worker (unpickled there once), or the
        # path each worker loads once; never once per task.
        shipped: Any = (
            shared if shared is not None else c.scatter(the_model, broadcast=True, hash=False)
        )
        futures = {}
        for name in todo:
            take = inputs[name][0]
            if isinstance(take, np.ndarray):
                take = c.scatter(take, hash=False)
            dest = out / f"{name}{OUTPUT_FORMATS[output]}"
            fut = c.submit(
                solve_shot,
                shipped,
                take,
                os.fspath(dest.resolve()),
                kind=output,
                options=options,
                allow_missing=allow_missing,
                take_units=take_units,
                fps=fps,
                threads=per_task,
                pure=False,
                key=f"lgi-shot-{name}-{os.urandom(4).hex()}",
            )
            futures[fut] = name
        for fut in as_completed(futures):
            name = futures[fut]
            try:
                rec = fut.result()
            except Exception as e:  # a worker died or the task could not run: this shot fails
                rec = {
                    "status": "failed",
                    "frames": None,
                    "seconds": None,
                    "output": None,
                    "error": f"{type(e).__name__}: {e}",
                }
            rec.update(input_hash=inputs[name][1], settings_hash=settings_hash)
            shot = _shot_of(name, rec)
            result[name] = shot
            records[name] = _record(shot)
            _write_manifest(manifest, model_info, records)
            bar.update(1)
            if shot.status != "done" and not quiet:
                bar.write(f"lgi batch: {name} failed: {shot.error}")
    return BatchResult(shots={n: result[n] for n in inputs}, manifest=manifest)


def _shot_of(name: str, rec: Mapping[str, Any], skipped: bool = False) -> Shot:
    """A manifest record (or a task's) as a `Shot`."""
    return Shot(
        name=name,
        status=str(rec.get("status")),
        frames=rec.get("frames"),
        seconds=rec.get("seconds"),
        output=rec.get("output"),
        error=rec.get("error"),
        input_hash=rec.get("input_hash"),
        settings_hash=str(rec.get("settings_hash")),
        skipped=skipped,
    )


def _exists(output: str) -> bool:
    """Whether a recorded output is still there (`NAME.NNNN.obj`: its first frame file)."""
    if output.endswith(".NNNN.obj"):
        return any(Path(output).parent.glob(Path(output).name.replace("NNNN", "[0-9]*")))
    return Path(output).is_file()
