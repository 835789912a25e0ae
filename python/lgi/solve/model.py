"""`lgi.Model`: build a Local Geometric Indexing model from a dataset and a marker layout, and
solve frames of markers into dense meshes. The heavy lifting is in the Rust core (GIL
released), each frame's jaw pose included; this layer adds progress bars and the jaw rig's
estimation at build. `BuildConfig` is the binding's (`lgi._lgi.BuildConfig`: fields, the
core's defaults and their documentation are defined there once), and so is the result
(`lgi._lgi.SolveResult`, `lgi._lgi.Choices`)."""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

import lgi._lgi as _lgi
from lgi._lgi import BuildConfig, SolveResult
from lgi.data.dataset import Dataset
from lgi.errors import InputError
from lgi.solve.detail import blend_detail, rest_positions
from lgi.solve.diagnose import diagnose, face_size
from lgi.solve.gaps import CONTEXT, fill_motion, filled
from lgi.solve.jaw import JawRig, auto_rig
from lgi.solve.local import local_pieces
from lgi.solve.motion import TakeMotion
from lgi.solve.options import UNBOUNDED, SolveOptions, local_bounds
from lgi.solve.repair import repaired
from lgi.solve.steady import RADIUS, marker_pulls, steadied, width_for
from lgi.solve.take_prior import TakePrior


def _bin_edges(jaw_bins: int | ArrayLike, shape_theta: NDArray[np.float64]) -> NDArray[np.float64]:
    """Bin edges over the jaw opening: given, or for an int n at quantiles of the shapes'
    distinct openings (repeated openings, such as the many expressions at rest, would make
    equal quantiles), the outer edges at the smallest and largest opening."""
    if isinstance(jaw_bins, (bool, np.bool_)):
        raise InputError(f"jaw_bins must be an int, a sequence of edges or None, got {jaw_bins!r}")
    if isinstance(jaw_bins, (int, np.integer)):
        n = int(jaw_bins)
        if n < 1:
            raise InputError(f"jaw_bins must be >= 1 bins, got {n}")
        if shape_theta.ndim != 2 or shape_theta.shape[1] != 3:
            raise InputError(f"shape_theta: expected shape (S, 3), got {shape_theta.shape}")
        raw = shape_theta[:, 0]
        if not np.all(np.isfinite(raw)):
            raise InputError("shape_theta: jaw openings must be finite")
        # Openings within 1e-6 rad of the previous one are the same opening (estimated poses
        # of expressions at rest scatter around 0 by round-off).
        ordered = np.sort(raw)
        opens = ordered[np.concatenate([[True], np.diff(ordered) > 1e-6])]
        if opens.size < 2:
            raise InputError(
                "jaw_bins: every dataset shape has the same jaw opening; binning needs shapes "
                "at different openings"
            )
        edges = np.quantile(opens, np.linspace(0.0, 1.0, n + 1))
        edges[0], edges[-1] = raw.min(), raw.max()
        return edges
    edges = np.asarray(jaw_bins)
    if edges.ndim != 1 or edges.dtype.kind not in "iuf":
        raise InputError(
            f"jaw_bins: expected an int or a 1-D sequence of edges (radians), got {jaw_bins!r}"
        )
    return edges.astype(np.float64)


def _labels(marker_names: Sequence[str] | None, units: str | None) -> dict[str, Any]:
    """`marker_names` and `units` checked for the core: names a sequence of str (the core
    checks count, uniqueness and form), the unit one lgi knows (normalised: `Millimeters` ->
    `mm`)."""
    from lgi.io.units import normalize_unit

    out: dict[str, Any] = {}
    if marker_names is not None:
        if isinstance(marker_names, str) or not all(isinstance(n, str) for n in marker_names):
            raise InputError("marker_names must be a sequence of str, one per marker")
        out["marker_names"] = list(marker_names)
    if units is not None:
        out["units"] = normalize_unit(units, "units")
    return out


#: Seconds a solve's progress bar waits before it is drawn: the arguments are checked in the
#: first moments of a call, and a call refused there should show its error, not "0/F".
PROGRESS_DELAY = 0.5


def _progress_bar(total: int, desc: str, quiet: bool) -> Any:
    from tqdm import tqdm

    return tqdm(
        total=total,
        desc=desc,
        unit="frame",
        disable=quiet or total < 2,
        leave=False,
        delay=PROGRESS_DELAY,
    )


class Model:
    """A built LGI model: immutable; `solve` may be called from several threads."""

    def __init__(self, core: _lgi.Model) -> None:
        self._core = core

    @classmethod
    def build(
        cls,
        dataset: Dataset,
        markers_rest: ArrayLike,
        config: BuildConfig | None = None,
        *,
        jaw: JawRig | str | None = "auto",
        shape_theta: ArrayLike | None = None,
        jaw_bins: int | ArrayLike | None = None,
        bin_overlap: float = 0.0,
        marker_names: Sequence[str] | None = None,
        units: str | None = None,
    ) -> Model:
        """Builds the model for `dataset` and marker rest positions `markers_rest` (B, 3).

        With a jaw rig (`lgi.solve.jaw.estimate_rig` gives one and `shape_theta`, the jaw pose
        (open, lateral, forward) of every dataset shape), shapes are unskinned before indexing
        (paper Eq. 2) and `solve(frames, jaw=...)` unskins and reskins each frame.

        `jaw_bins` bins the point clouds by jaw opening (the paper's suggestion for datasets
        scanned at many openings): an int n gives n bins with edges at quantiles of the
        shapes' distinct openings (first edge the smallest, last the largest); a sequence
        gives the edges (radians, strictly increasing). Each bin holds the shapes whose
        opening lies in its range widened by `bin_overlap` (radians) on both sides, re-posed
        to the bin's middle opening; each frame uses the bin of its jaw opening (keeping the
        previous frame's bin while the opening stays in its widened range). None (default):
        one set of clouds with every shape.

        `jaw="auto"` (default): a dataset with a `jawOpen` shape gets the rig
        `lgi.solve.jaw.estimate_rig` finds in its jaw shapes (a warning and no rig when it finds
        none), so `solve` turns the jaw as a rotation rather than blending it linearly
        (docs/results.md measures what it gives); `jaw=None` builds without a rig.

        `marker_names` (B unique names, e.g. from `lgi.io.takes.read_layout`) and `units` (the
        coordinates' length unit, a key of `lgi.io.units.METERS_PER_UNIT`) are kept with the
        model (and its file): takes are matched to it by label and converted to its units.
        Default: names `m000`, `m001`, ... and no unit."""
        labels = _labels(marker_names, units)
        if isinstance(jaw, str):
            if jaw != "auto":
                raise InputError(f"jaw must be 'auto', a JawRig or None, got {jaw!r}")
            if shape_theta is not None:
                raise InputError("shape_theta goes with a JawRig, not jaw='auto'")
            jaw, shape_theta = auto_rig(dataset)
            if jaw is None and jaw_bins is not None:
                raise InputError("jaw_bins: the dataset has no jawOpen shape to bin by")
        if jaw is None:
            if shape_theta is not None:
                raise InputError("shape_theta was given without a jaw rig")
            if jaw_bins is not None:
                raise InputError("jaw_bins needs a jaw rig (jaw=...) and shape_theta")
            return cls(_lgi.Model.build(dataset.core, markers_rest, config, **labels))
        if shape_theta is None:
            raise InputError("a jaw rig needs shape_theta: the jaw pose of every dataset shape")
        theta = np.asarray(shape_theta, dtype=np.float64)
        edges = None if jaw_bins is None else _bin_edges(jaw_bins, theta)
        try:
            overlap = float(bin_overlap)
        except (TypeError, ValueError):
            raise InputError(f"bin_overlap must be a number, got {bin_overlap!r}") from None
        core = _lgi.Model.build(
            dataset.core,
            markers_rest,
            config,
            jaw_pivot=jaw.pivot,
            jaw_weights=jaw.weights,
            shape_theta=theta,
            jaw_bins=edges,
            bin_overlap=overlap,
            jaw_frame=jaw.frame,
            **labels,
        )
        return cls(core)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Model:
        """Loads a model written by `save`."""
        return cls(_lgi.Model.load(os.fspath(path)))

    def save(self, path: str | os.PathLike[str]) -> None:
        """Writes the model (versioned binary `.lgi` file)."""
        self._core.save(os.fspath(path))

    def to_bytes(self) -> bytes:
        """The bytes `save` writes (the versioned model format, checksum included)."""
        return self._core.to_bytes()

    @classmethod
    def from_bytes(cls, data: bytes | bytearray) -> Model:
        """A model from `to_bytes` (or a model file's bytes), with every check of `load`:
        corrupt or truncated bytes raise `lgi.ModelFormatError`."""
        return cls(_lgi.Model.from_bytes(data))

    def __reduce__(self) -> tuple[Any, tuple[bytes]]:
        # Pickled as the model file's bytes: a worker process gets a model exactly as valid
        # as one loaded from a file, and solves bit-identically.
        return (Model.from_bytes, (self.to_bytes(),))

    @property
    def num_bundles(self) -> int:
        return self._core.num_bundles

    @property
    def num_vertices(self) -> int:
        return self._core.num_vertices

    @property
    def diagonal(self) -> float:
        """Bounding-box diagonal of the neutral: the unit of relative tolerances."""
        return self._core.diagonal

    @property
    def dataset(self) -> Dataset:
        return Dataset(self._core.dataset)

    @property
    def markers_rest(self) -> NDArray[np.float64]:
        return self._core.markers_rest

    @property
    def marker_names(self) -> list[str]:
        """Each marker's name (B): the layout's, or `m000`, `m001`, ... when built without
        names (and for files of format version 3 and older)."""
        return self._core.marker_names

    @property
    def units(self) -> str | None:
        """The coordinates' length unit given at build (`cm`, `mm`, ...); None if not given."""
        return self._core.units

    @property
    def config(self) -> BuildConfig:
        """The build parameters (a loaded model's too)."""
        return self._core.config

    @property
    def jaw_rig(self) -> JawRig | None:
        """The jaw rig the model was built with (None without one)."""
        return self._core.jaw_rig

    @property
    def jaw_bins(self) -> NDArray[np.float64] | None:
        """Edges (K + 1,) of the jaw-opening bins (radians), None for an unbinned model."""
        j = self._core.jaw()
        return None if j is None or "bin_edges" not in j else j["bin_edges"]

    @property
    def core(self) -> _lgi.Model:
        """The compiled model, for low-level inspection (weights, neighbours, statistics)."""
        return self._core

    def solve(
        self,
        frames: ArrayLike,
        *,
        temporal: bool = True,
        steady: bool | None = None,
        jaw: str | ArrayLike | None = "auto",
        smooth_window: int = 0,
        quiet: bool = False,
        out: NDArray[np.float64] | None = None,
        marker_noise: float | None = None,
        fit: bool | str | None = None,
        detail_weight: float | None = None,
        local_fits: bool | str = False,
        take_prior: TakePrior | None = None,
        repair: bool | None = None,
        fault_noise: float | None = None,
        options: SolveOptions | None = None,
    ) -> SolveResult:
        """Solves frames (F, B, 3) of marker positions (a single (B, 3) frame gives F = 1).
        NaN rows are missing markers. With `temporal` (a performance), frames are solved in
        order and each prefers the previous frame's choices; `temporal=False` treats frames as
        independent (e.g. one frame per dataset shape) and solves them in parallel.

        `steady` (default True; with `temporal`, the frames a take's consecutive frames): a missing
        marker sample is filled from the take before the frame is solved (its low-rank motion
        given the frame's other markers, or the marker's neighbours, as the take's held-out
        samples say: `lgi.solve.gaps`; it stays missing in the result), and the dataset's detail
        between the markers is averaged over neighbouring frames (`lgi.solve.steady`; every
        marker stays where the solve put it), so a dropout or a flip between two pieces of
        local geometry does not pop. `steady=False` for frames that are not consecutive (a
        take subsampled in time).

        `jaw` (models built with a jaw rig): `"auto"` (default) and `"fit"` start each frame's
        jaw pose from its global blendshape fit (the shapes' poses weighted by their fitted
        weights) and refine it to the pose whose jaw-unskinned markers the dataset explains
        best (Gauss-Newton in the core); `"track"` fits the markers the jaw carries rigidly
        (a Huber-robust fit per frame from the previous frame's pose, averaged over 5 frames;
        biased where lips and chin move with other shapes); an (F, 3) array gives the poses;
        None solves at the rest pose. Without a rig, `"auto"` is None. The poses used are in
        `result.jaw_theta`; with jaw bins (`Model.build(jaw_bins=...)`) the bin each frame
        used is in `result.jaw_bin`.

        `smooth_window` > 1 averages each marker's shape weights over that many frames
        (centred) before sewing, in the jaw-unskinned space so jaw motion is kept; markers are
        still interpolated exactly. `result.choices` are the choices before smoothing.

        `out`: a C-contiguous, writeable float64 array of shape (F, V, 3) that receives the
        vertices (`result.vertices` is then `out`), for pipelines that solve chunk after chunk
        into one buffer instead of allocating a new one per call.

        `marker_noise`: the markers. noise sigma (data units, per coordinate; e.g. 0.05 for 0.5 mm
        in cm; `lgi.estimate_marker_noise` estimates it from a take). Each marker is first
        moved to the frame's global blendshape fit plus the fit's residual smoothed across
        neighbouring markers (independent noise, a spike or a swapped label is pulled in, a
        residual that neighbours share is kept where they share it), then interpolated;
        `result.marker_corrections` says how far.
        None (default): every marker is interpolated as given (the paper's mode).

        `fit`: every bundle may take the frame's global blendshape fit instead of one of its
        tets, chosen by the same neighbour score (frames with many shapes active at once);
        False is the paper's method, tets only. Default (None): on exactly when `marker_noise`
        is given (`marker_noise=0` for noise-free markers), so the recommended call on real
        capture is `solve(frames, marker_noise=sigma)`. Not offered with `smooth_window`. The
        fit costs time with many shapes (docs/performance.md). `fit="unbounded"`
        (`lgi.solve.local.UNBOUNDED`): the fit is offered and its weights are not held to [0, 1]
        (least squares with the fit's ridge alone, at the jaw pose the boxed fit refined): for a
        dataset of whole-face scans, whose weights are no activations (docs/concepts.md).

        `detail_weight` in [0, 1]: how much of the dataset's detail between the markers to keep
        (`lgi.plan.detail`; `lgi.estimate_detail_weight` reads it from a take): the result is
        `w * solved + (1 - w) * smooth`, the smooth part the biharmonic interpolation of the
        solve's own present marker positions. None or 1 (default): the solve as it is.

        `local_fits`: each bundle's piece is the blendshape fit of the markers around it
        (`lgi.solve.local`) instead of one of its tets or the frame's global fit; the pieces' blend
        is put through the solve's targets by a biharmonic corrective. Needs `marker_noise` (its
        targets, poses and global fits) and a model without jaw bins. With a dataset of whole-face
        scans it is the most accurate path measured (docs/results.md); it costs a fit per bundle and
        frame (docs/performance.md). Each window's weights are held to
        [0, 1] like the global fit's (a FACS rig's activations); `local_fits="unbounded"`
        (`lgi.solve.local.UNBOUNDED`) drops that bound, for a dataset of scans whose differences
        match a region as well as their sums (docs/concepts.md), and so does the frame's global
        fit the windows start from and the targets come from (as `fit="unbounded"`).

        `take_prior` (`lgi.estimate_take_prior`, with an unbounded global fit): the take's own
        prior on the fit's weights in place of its ridge, so a noisy frame keeps to the
        directions the take moves in (docs/concepts.md).

        `repair` (default True; with `steady`, a take's consecutive frames): the marker faults
        the solve shows (`lgi.solve.diagnose`: a label swap, a spike, a marker off its track;
        never a model gap) are repaired on a copy of the frames (`lgi.solve.repair`: the swap
        undone, the others solved as missing and filled) and the frames solved again;
        `result.repairs` lists the faults repaired (empty: none found) and `result.repaired`
        marks the samples changed. `repair=False` keeps the markers as given. Faults are read at
        `fault_noise` (the markers' noise as the take gave them; None: `marker_noise`): a plan
        of a denoised take sets it (`lgi.plan_solve`), as `lgi solve` reads the given markers."""
        opts, jaw = self._options(
            options,
            jaw,
            marker_noise=marker_noise,
            fit=fit,
            detail_weight=detail_weight,
            local_fits=local_fits,
            take_prior=take_prior,
            steady=steady,
            repair=repair,
            fault_noise=fault_noise,
        )
        arr = np.asarray(frames)
        if arr.ndim == 2:
            arr = arr[None]

        def once(x: NDArray[Any]) -> SolveResult:
            return self._solved(
                x,
                opts,
                temporal=temporal,
                jaw=jaw,
                smooth_window=smooth_window,
                quiet=quiet,
                out=out,
            )

        res = once(arr)
        if not (temporal and opts.steady and opts.repair and arr.shape[0] >= 2):
            return res
        names = self.marker_names
        found = diagnose(
            res.bundle_residuals,
            res.missing,
            names,
            size=face_size(np.asarray(res.vertices)[0]),
            markers=arr,
            noise=opts.given_noise,
        )
        faults = tuple(f for f in found if f.fault)
        if not faults:
            return _with(res, repairs=())
        fixed, changed, _ = repaired(np.asarray(arr, dtype=np.float64), faults, names)
        again = once(fixed)
        return _with(again, repaired=changed, repairs=faults)

    def solve_markers(
        self,
        frames: ArrayLike,
        *,
        jaw: str | None = "auto",
        marker_noise: float | None = None,
        fit: bool | str | None = None,
        take_prior: TakePrior | None = None,
    ) -> SolveResult:
        """`frames` (F, B, 3) solved as independent frames, as `solve(frames, temporal=False,
        ...)` with the same options solves them, for their markers alone: each marker's
        position on its frame's solved surface (the same bits as `solve`'s), the residuals,
        choices, global fits and jaw poses; the surfaces are not made (only the markers'
        triangles are sewn), and the result's `vertices` are an empty (F, 0, 3) array. What
        a take's left-out readings need (`lgi.plan`), at a fraction of a solve's cost."""
        opts, jaw = self._options(
            None, jaw, marker_noise=marker_noise, fit=fit, take_prior=take_prior
        )
        offer, unbounded, prior, sigma = _core_fit(opts)
        arr = np.asarray(frames)
        return self._core.solve(
            arr[None] if arr.ndim == 2 else arr,
            temporal=False,
            jaw=jaw,
            fit=offer,
            marker_noise=sigma,
            unbounded_fit=unbounded,
            take_prior=prior,
            surface="markers",
        )

    def _solved(
        self,
        arr: NDArray[Any],
        opts: SolveOptions,
        *,
        temporal: bool,
        jaw: Any,
        smooth_window: int,
        quiet: bool,
        out: NDArray[np.float64] | None,
    ) -> SolveResult:
        """One solve of `arr` (`solve` without the repair)."""
        total = int(arr.shape[0]) if arr.ndim == 3 else 0
        given = arr
        steady = temporal and opts.steady
        motion = None
        if steady:
            motion = self._fill_motion(arr, opts)
            arr = self._gaps_filled(arr, motion)
        with _progress_bar(total, "lgi solve", quiet) as bar:
            res = self._core_solve(
                arr,
                opts,
                progress=lambda _f: bar.update(1),
                temporal=temporal,
                jaw=jaw,
                smooth_window=smooth_window,
                out=out,
            )
        if not steady:
            return self._finish(res, arr, opts)
        res, misses = self._finish_steadied(res, arr, opts)
        v, p = np.asarray(res.vertices), np.asarray(res.bundle_positions)
        pulls = marker_pulls(np.asarray(given, dtype=np.float64), p, opts.solve_noise)
        width = width_for(opts)
        v = steadied(self, v, p, misses=misses, pulls=pulls, width=width)
        return self._as_given(res, v, given, motion, pulls)

    def _core_solve(
        self,
        frames: NDArray[Any],
        opts: SolveOptions,
        *,
        progress: Any,
        temporal: bool,
        jaw: Any,
        out: NDArray[np.float64] | None,
        smooth_window: int = 0,
        previous: _lgi.SolveState | None = None,
    ) -> SolveResult:
        """The core's solve of `frames` with `opts`. With local fits, whose surface replaces
        the core's, the core makes no surface (`surface="none"`: the targets, fits and poses
        they read), and the vertices go into `out` or a new (F, V, 3) array, which
        `_finish` fills."""
        offer, unbounded, prior, sigma = _core_fit(opts)
        own_surface = local_bounds(opts.local_fits) is not None
        if own_surface and out is None and frames.ndim == 3:
            out = np.empty((frames.shape[0], self.num_vertices, 3))
        return self._core.solve(
            frames,
            progress=progress,
            temporal=temporal,
            jaw=jaw,
            smooth_window=smooth_window,
            out=out,
            fit=offer,
            marker_noise=sigma,
            previous=previous,
            unbounded_fit=unbounded,
            take_prior=prior,
            surface="none" if own_surface else "mesh",
        )

    def _options(
        self, options: SolveOptions | None, jaw: Any, **given: Any
    ) -> tuple[SolveOptions, Any]:
        """The solve's options, built and checked once (`SolveOptions`, from `options` or the
        keywords `given`, not both), and the core's `jaw`: the options' mode, or the poses
        given as an array."""
        for flag in ("steady", "repair"):  # None: the options' own (True unless given)
            if given.get(flag) is None:
                given.pop(flag, None)
        if options is None:
            mode = jaw if jaw is None or isinstance(jaw, str) else "auto"
            opts = SolveOptions(jaw=mode, **given)
        elif not isinstance(options, SolveOptions):
            raise InputError(f"options: expected an lgi.SolveOptions, got {type(options).__name__}")
        else:
            # Every keyword left at its default (None or False) when options= is given.
            named = (
                "steady" in given
                or "repair" in given
                or any(v is not None and v is not False for v in given.values())
            )
            if jaw != "auto" or named:
                raise InputError(
                    "give a solve's options either as options= or as keywords, not both"
                )
            opts, jaw = options, options.jaw
        opts.check_resolved()
        opts.check_model(self.jaw_bins is not None)
        return opts, jaw

    def _gaps_filled(self, frames: NDArray[Any], motion: TakeMotion | None) -> NDArray[Any]:
        """A take's frames with the missing samples it can fill filled (`lgi.solve.gaps`; a row
        with any NaN is missing, as the core reads it) by the take's `motion` (`_fill_motion`;
        None: by the markers' neighbours); frames the core will refuse (shape, dtype, an
        infinite value) go to it as given, so its error names the problem."""
        if not self._fillable(frames):
            return frames
        return filled(frames, rest_positions(self), motion)[0]

    def _fillable(self, frames: NDArray[Any]) -> bool:
        """Whether `frames` are a take whose gaps `_gaps_filled` fills: (F ≥ 2, B, 3) floats,
        some missing, every present value finite."""
        if (
            frames.ndim != 3
            or frames.dtype.kind != "f"
            or frames.shape[1:] != (self.num_bundles, 3)
            or frames.shape[0] < 2
        ):
            return False
        nan = np.isnan(frames)
        return bool(nan.any()) and bool(np.isfinite(frames[~nan]).all())

    def _fill_motion(self, frames: NDArray[Any], opts: SolveOptions) -> TakeMotion | None:
        """The take's motion its gaps are filled by (`lgi.solve.gaps.fill_motion`: None, by the
        markers' neighbours), read at the markers' noise as the take gave them."""
        if not self._fillable(frames):
            return None
        sigma = opts.given_noise or 0.0
        return fill_motion(np.asarray(frames, dtype=np.float64), rest_positions(self), sigma)

    def _as_given(
        self,
        res: SolveResult,
        vertices: NDArray[np.float64],
        given: NDArray[Any],
        motion: TakeMotion | None,
        pulls: NDArray[np.float64] | None,
    ) -> SolveResult:
        """`res` of a take's gap-filled frames with its steadied `vertices`, reported against the
        frames `given`: a filled sample is missing (residual 0), as the take had it; the fill's
        rank where the take's `motion` filled some, and the markers' `pulls`."""
        missing = np.asarray(res.missing) | np.isnan(given).any(axis=2)
        moved = res.marker_corrections
        filled = missing & ~np.asarray(res.missing)  # missing as given, solved as filled
        return _with(
            res,
            vertices=vertices,
            bundle_residuals=np.where(missing, 0.0, np.asarray(res.bundle_residuals)),
            missing=missing,
            marker_corrections=None if moved is None else np.where(missing, 0.0, moved),
            filled=filled,
            fill_rank=motion.rank if motion is not None and filled.any() else None,
            marker_pulls=pulls,
        )

    def _finish(self, res: SolveResult, frames: NDArray[Any], opts: SolveOptions) -> SolveResult:
        """`res` with its local fits' surface and then the weight of its detail (`opts`)."""
        bounded = local_bounds(opts.local_fits)
        if bounded is not None:
            res = self._with_local(res, frames, bounded)
        weight = opts.detail_weight
        if weight is None or weight == 1.0:
            return res
        return self._with_detail(res, frames, float(weight))

    def _finish_steadied(
        self, res: SolveResult, frames: NDArray[Any], opts: SolveOptions
    ) -> tuple[SolveResult, NDArray[np.float64] | None]:
        """`_finish` for a whole take steadied next: with local fits (every marker solved, the
        detail kept whole) their corrective is left to `steadied`, which adds one over the mesh
        anyway: the vertices are the posed blend, the positions and residuals the whole
        surface's, and the misses returned (else None, `_finish`)."""
        bounded = local_bounds(opts.local_fits)
        weight = opts.detail_weight
        whole = weight is None or weight == 1.0
        if bounded is None or not whole or np.asarray(res.missing).any():
            return self._finish(res, frames, opts), None
        v = np.asarray(res.vertices)
        _, pos, misses = local_pieces(self).posed_and_misses(res, v, bounded=bounded)
        return self._remeasured(res, v, frames, pos), misses

    def _with_local(self, res: SolveResult, frames: NDArray[Any], bounded: bool) -> SolveResult:
        """`res` with the local fits' surface (`lgi.plan.local`) in place in its vertices (an `out`
        buffer receives it), its marker positions and residuals measured again."""
        v = np.asarray(res.vertices)
        _, pos = local_pieces(self).surface_and_markers(res, out=v, bounded=bounded)
        return self._remeasured(res, v, frames, pos)

    def _remeasured(
        self,
        res: SolveResult,
        v: NDArray[np.float64],
        frames: NDArray[Any],
        pos: NDArray[np.float64] | None = None,
    ) -> SolveResult:
        """`res` with vertices `v`, its marker positions (`pos`, where already measured) and
        residuals measured on them."""
        missing = np.asarray(res.missing)
        pos = self.bundle_positions(v) if pos is None else pos
        given = np.asarray(frames, dtype=np.float64)
        residuals = np.where(missing, 0.0, np.linalg.norm(np.nan_to_num(given - pos), axis=2))
        return _with(res, vertices=v, bundle_residuals=residuals, bundle_positions=pos)

    def _with_detail(self, res: SolveResult, frames: NDArray[Any], weight: float) -> SolveResult:
        """`res` with `weight` of its detail kept (`lgi.solve.detail.blend_detail`, in place in its
        vertices, so an `out` buffer receives the result), its marker positions and residuals
        measured again on the blended surface."""
        missing = np.asarray(res.missing)
        v = blend_detail(self, res.vertices, np.asarray(res.bundle_positions), missing, weight)
        return self._remeasured(res, v, frames)

    def solve_iter(
        self,
        frames: ArrayLike,
        *,
        chunk: int = 256,
        temporal: bool = True,
        steady: bool | None = None,
        jaw: str | None = "auto",
        quiet: bool = False,
        out: NDArray[np.float64] | None = None,
        marker_noise: float | None = None,
        fit: bool | str | None = None,
        detail_weight: float | None = None,
        local_fits: bool | str = False,
        take_prior: TakePrior | None = None,
        options: SolveOptions | None = None,
    ) -> Iterator[SolveResult]:
        """Solves `frames` (F, B, 3; a numpy memmap keeps a long take on disk) `chunk` frames
        at a time and yields each chunk's `SolveResult`, so memory stays flat however long
        the take. A temporal solve continues across chunks (each starts from the last frame's
        choices and jaw bin of the one before), so the chunks together equal `solve(frames)`
        bit for bit, except with `jaw="track"` (poses tracked chunk by chunk). `out`: a
        (chunk, V, 3) float64 buffer every chunk is written into (a yielded result's vertices
        are then overwritten by the next chunk: copy what you keep). Smoothing is not offered
        (it needs frames beyond the chunk); give poses as arrays by solving chunks with
        `solve`. Other options as in `solve` (`detail_weight` applied chunk by chunk: each
        frame's blend is its own, and `local_fits` too; `take_prior` is the whole take's; `steady`
        fills and steadies each chunk with the frames around it, so the chunks still equal one
        solve; `repair` is not applied, since it reads the whole take's residuals: solve the
        take with `solve`, and a chunk's `repairs` is None)."""
        if jaw is not None and not isinstance(jaw, str):
            raise InputError("solve_iter: jaw must be 'auto', 'fit', 'track' or None")
        opts, jaw = self._options(
            options,
            jaw,
            marker_noise=marker_noise,
            fit=fit,
            detail_weight=detail_weight,
            local_fits=local_fits,
            take_prior=take_prior,
            steady=steady,
        )
        n = _lgi.check_count(chunk, "chunk")
        if n < 1:
            raise InputError(f"chunk must be >= 1 frames, got {n}")
        arr = frames if isinstance(frames, np.ndarray) else np.asarray(frames)
        if arr.ndim != 3:
            raise InputError(f"frames must have shape (F, B, 3), got {arr.shape}")
        total = int(arr.shape[0])
        steady = temporal and opts.steady
        state: _lgi.SolveState | None = None
        before: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None
        # Every chunk is filled by the whole take's motion, so the chunks equal one solve.
        motion = self._fill_motion(np.asarray(arr), opts) if steady else None
        width = width_for(opts)

        def solved(part: NDArray[Any], buf: Any, previous: Any, tick: Any) -> SolveResult:
            res = self._core_solve(
                part, opts, progress=tick, temporal=temporal, jaw=jaw, out=buf, previous=previous
            )
            return self._finish(res, part, opts)

        with _progress_bar(total, "lgi solve", quiet) as bar:
            for a in range(0, total, n):
                b = min(total, a + n)
                if not steady:
                    part = np.asarray(arr[a:b])
                    buf = None if out is None else out[: b - a]
                    res = solved(part, buf, state, lambda _f: bar.update(1))
                    state = res.state if temporal else None
                    yield res
                    continue
                # A chunk's gaps are filled, and its detail steadied, from the frames around it
                # (`lgi.solve.gaps`, `lgi.solve.steady`), so the chunks equal one solve.
                lo, hi = max(0, a - CONTEXT), min(total, b + RADIUS + CONTEXT)
                given = np.asarray(arr[lo:hi])
                window = self._gaps_filled(given, motion)
                part = window[a - lo : b - lo]
                buf = None if out is None else out[: b - a]
                res = solved(part, buf, state, lambda _f: bar.update(1))
                state = res.state
                v = np.asarray(res.vertices)
                after = None
                if b < total:
                    ahead = window[b - lo : min(total, b + RADIUS) - lo]
                    nxt = solved(ahead, None, state, None)
                    after = (np.asarray(nxt.vertices), np.asarray(nxt.bundle_positions))
                p = np.asarray(res.bundle_positions)
                tail = (v[-RADIUS:].copy(), p[-RADIUS:].copy())
                mine = np.asarray(given[a - lo : b - lo], dtype=np.float64)
                pulls = marker_pulls(mine, p, opts.solve_noise)
                steadied(self, v, p, first=a, before=before, after=after, pulls=pulls, width=width)
                before = (
                    tail
                    if before is None
                    else (
                        np.concatenate([before[0], tail[0]])[-RADIUS:],
                        np.concatenate([before[1], tail[1]])[-RADIUS:],
                    )
                )
                yield self._as_given(res, v, given[a - lo : b - lo], motion, pulls)

    def bundle_positions(self, meshes: ArrayLike) -> NDArray[np.float64]:
        """Marker surface positions (F, B, 3) on meshes (F, V, 3) or (V, 3) -> (B, 3)."""
        arr = np.asarray(meshes)
        if arr.ndim == 2:
            return self._core.bundle_positions(arr[None])[0]
        return self._core.bundle_positions(arr)

    def __repr__(self) -> str:
        return f"Model(num_bundles={self.num_bundles}, num_vertices={self.num_vertices})"


def _with(res: SolveResult, **fields: Any) -> SolveResult:
    """`res` with `fields` replaced (the binding's result is immutable)."""
    keep = {
        "vertices": res.vertices,
        "bundle_residuals": res.bundle_residuals,
        "bundle_positions": res.bundle_positions,
        "missing": res.missing,
        "choices": res.choices,
        "jaw_theta": res.jaw_theta,
        "jaw_bin": res.jaw_bin,
        "marker_corrections": res.marker_corrections,
        "fit_weights": res.fit_weights,
        "state": res.state,
        "filled": res.filled,
        "repaired": res.repaired,
        "repairs": res.repairs,
        "fill_rank": res.fill_rank,
        "marker_pulls": res.marker_pulls,
    }
    return SolveResult(**{**keep, **fields})


def _core_fit(
    opts: SolveOptions,
) -> tuple[
    bool | None,
    bool,
    tuple[NDArray[np.float64], NDArray[np.float64], float] | None,
    float | None,
]:
    """The core's `fit`, `unbounded_fit`, `take_prior` and `marker_noise` for checked, resolved
    options: unbounded local fits start from an unbounded global fit; the take prior is a prior
    on that fit."""
    fit = opts.fit
    offer, unbounded = (True, True) if fit == UNBOUNDED else (fit, False)
    if local_bounds(opts.local_fits) is False:
        unbounded = True
    prior = opts.take_prior.as_core() if isinstance(opts.take_prior, TakePrior) else None
    return offer, unbounded, prior, opts.solve_noise  # type: ignore[return-value]
