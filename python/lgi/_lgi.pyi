"""Type stubs for the compiled extension ``lgi._lgi`` (users import ``lgi``)."""

import os
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Literal, TypedDict, final

import numpy as np
from numpy.typing import ArrayLike, NDArray
from typing_extensions import NotRequired, Self

__all__ = [
    "FIT_L2",
    "FIT_PENALTY",
    "LOCAL_LENGTH",
    "MAGNITUDE_LIMIT",
    "MAX_THREADS",
    "MIN_PRESENT_MARKERS",
    "BlendshapeSolver",
    "BuildConfig",
    "Choices",
    "Dataset",
    "JawRig",
    "LocalFits",
    "LocalSurface",
    "Model",
    "RbfInterpolator",
    "SolveResult",
    "SolveState",
    "__version__",
    "blend_local",
    "check_count",
    "check_marker_frames",
    "closest_surface_points",
    "fill_missing_rows",
    "get_num_threads",
    "set_num_threads",
    "shape_basis",
]

__version__: str
FIT_L2: float
MIN_PRESENT_MARKERS: int
FIT_PENALTY: float
LOCAL_LENGTH: float
MAGNITUDE_LIMIT: float
MAX_THREADS: int

def set_num_threads(n: int | None) -> None:
    """lgi's parallel work runs on a pool of ``n`` threads (1..MAX_THREADS) from the next call
    on; None: rayon's global pool again. A second call replaces the pool."""

def get_num_threads() -> int:
    """The number of threads lgi's parallel work runs on now."""

def check_count(value: object, name: str) -> int:
    """`value` as a count (an int >= 0); else `lgi.InputError` naming `name`."""

def blend_local(
    neutral: ArrayLike,
    shapes: NDArray[np.float32],
    indptr: NDArray[np.int64],
    indices: NDArray[np.int64],
    data: NDArray[np.float64],
    weights: ArrayLike,
) -> NDArray[np.float64]:
    """The local fits' blend (F, V, 3): vertex v of frame f is ``neutral[v] + sum_j (sum_b
    s_vb weights[f, b, j]) shapes[v, :, j]``, s the sewing weights as CSR rows (``indptr``
    (V+1,), ``indices``, ``data``), ``shapes`` (V, 3, q) float32 C-contiguous, ``weights``
    (F, B, q)."""

def shape_basis(
    shapes: NDArray[np.float32],
) -> tuple[NDArray[np.int64], NDArray[np.float64]] | None:
    """``shapes`` (S, N) float32, C-contiguous: None when no shape is a combination of the
    others, else the basis shapes' indices (q,) and every shape's coefficients over them
    (S, q), a combination counted to a relative rms of 1e-6."""

def check_marker_frames(frames: ArrayLike, markers_rest: ArrayLike, diagonal: float) -> None:
    """Raise `lgi.InputError` (naming frame and marker) for frames (F, B, 3) that break the
    magnitude policy of every method."""

def closest_surface_points(
    vertices: ArrayLike, triangles: ArrayLike, points: ArrayLike
) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Each of ``points`` (P, 3)'s closest point on the mesh: the row of ``triangles`` it lies
    on (P,) (the lowest on a tie) and its barycentric coordinates (P, 3)."""

def fill_missing_rows(
    u: NDArray[np.float64],
    l: NDArray[np.float64],
    k: NDArray[np.float64],
    present: NDArray[np.bool_],
    zeta: NDArray[np.float64],
    mean: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """``zeta`` (F, q) with every frame short of a row (``present`` (F, R) bool) filled by its
    fit in the fit matrix's coordinates: ``u`` and the fit's left factor ``l`` (R, q), ``k = l
    @ u.T`` (R, R); with ``mean`` (q,), under the prior of that mean. All C-contiguous
    float64 (``lgi.plan.take_prior``)."""

_Path = str | os.PathLike[str]

@final
class Dataset:
    """The core's dataset: neutral mesh plus S shapes (displacements). Immutable; cheap to
    share. ``lgi.Dataset`` holds one (its ``core``)."""

    @staticmethod
    def from_obj(neutral: _Path, shapes: _Path | Sequence[_Path] | None = None) -> Dataset:
        """Neutral OBJ plus shape OBJs: a glob pattern (sorted matches), paths, or None."""
    @staticmethod
    def from_gltf(path: _Path) -> Dataset:
        """First mesh of a glTF/GLB file; morph targets are the shapes."""
    def to_bytes(self) -> bytes:
        """The model file's dataset part as bytes (magic ``LGIDATAS``)."""
    @staticmethod
    def from_bytes(data: bytes | bytearray) -> Dataset:
        """A dataset from ``to_bytes``; corrupt bytes raise ``lgi.ModelFormatError``."""
    def __reduce__(self) -> tuple[Callable[[bytes], Dataset], tuple[bytes]]: ...
    @staticmethod
    def from_arrays(
        neutral: ArrayLike,
        triangles: ArrayLike,
        shapes: ArrayLike | None = None,
        names: Sequence[str] | None = None,
        uvs: ArrayLike | None = None,
        uv_triangles: ArrayLike | None = None,
    ) -> Dataset:
        """neutral (V, 3) float, triangles (T, 3) int, shapes (S, V, 3) float displacements,
        names (S,), uvs (U, 2) float and uv_triangles (T, 3) int (both or neither)."""
    def augmented(self, min_shapes: int) -> Dataset:
        """Adds in-betweens (``name@0.5``) and pairwise sums of displacements, to at least
        ``min_shapes`` (``lgi.Dataset.augmented`` adds the ARAP method)."""
    def augment_recipes(self, min_shapes: int) -> list[tuple[str, list[tuple[int, float]]]]:
        """``(name, [(shape, weight), ...])`` of each shape ``augmented(min_shapes)`` makes."""
    @property
    def num_vertices(self) -> int: ...
    @property
    def num_shapes(self) -> int: ...
    @property
    def names(self) -> list[str]: ...
    @property
    def neutral(self) -> NDArray[np.float64]:
        """(V, 3) neutral positions."""
    @property
    def shapes(self) -> NDArray[np.float32]:
        """(S, V, 3) displacements."""
    @property
    def triangles(self) -> NDArray[np.int64]:
        """(T, 3) vertex indices."""
    @property
    def uvs(self) -> NDArray[np.float64]:
        """(U, 2) UV coordinates."""
    def with_polygons(
        self, counts: ArrayLike, vertices: ArrayLike, uvs: ArrayLike | None = None
    ) -> Dataset:
        """A new dataset with the neutral's source faces (fan-splitting into its triangles)."""
    @property
    def polygons(
        self,
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]] | None:
        """The neutral's source faces (OBJ): ``(counts, vertices, uvs)``; None otherwise."""
    @property
    def uv_triangles(self) -> NDArray[np.int64]:
        """(T, 3) UV indices (empty when the mesh has no UVs)."""

@final
class BuildConfig:
    """Build parameters (the core's defaults; fields documented on the class at runtime)."""

    def __new__(
        cls,
        surface_tolerance: float | None = None,
        prune_motion: float | None = None,
        duplicate_distance: float | None = None,
        tet_neighbours: int | None = None,
        max_tets: int | None = None,
        min_quality: float | None = None,
        max_edge: float | None = None,
        containment_eps: float | None = None,
        projection_candidates: int | None = None,
        temporal_weight: float | None = None,
        detour_ratio: float | None = None,
    ) -> BuildConfig: ...
    @property
    def surface_tolerance(self) -> float: ...
    @property
    def prune_motion(self) -> float: ...
    @property
    def duplicate_distance(self) -> float: ...
    @property
    def tet_neighbours(self) -> int: ...
    @property
    def max_tets(self) -> int: ...
    @property
    def min_quality(self) -> float: ...
    @property
    def max_edge(self) -> float: ...
    @property
    def containment_eps(self) -> float: ...
    @property
    def projection_candidates(self) -> int: ...
    @property
    def temporal_weight(self) -> float: ...
    @property
    def detour_ratio(self) -> float: ...
    def replace(self, **changes: float) -> BuildConfig: ...
    def to_dict(self) -> dict[str, float | int]: ...
    def __eq__(self, other: object, /) -> bool: ...
    def __hash__(self) -> int: ...
    def __getnewargs_ex__(self) -> tuple[tuple[()], dict[str, float | int]]: ...

@final
class JawRig:
    """Two-bone jaw rig: pivot, per-vertex weights, axes (``frame`` columns)."""

    def __new__(
        cls, pivot: ArrayLike, weights: ArrayLike, frame: ArrayLike | None = None
    ) -> Self: ...
    @property
    def pivot(self) -> NDArray[np.float64]: ...
    @property
    def weights(self) -> NDArray[np.float64]: ...
    @property
    def frame(self) -> NDArray[np.float64]: ...
    @property
    def num_vertices(self) -> int: ...
    def transform(self, theta: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """R (3, 3), t (3,): a weight-1 point moves to R (p - pivot) + pivot + t."""
    def skin(
        self, points: ArrayLike, theta: ArrayLike, weights: ArrayLike | None = None
    ) -> NDArray[np.float64]:
        """(N, 3) points to pose (3,), or (F, N, 3) to (3,) or (F, 3) poses."""
    def unskin(
        self, points: ArrayLike, theta: ArrayLike, weights: ArrayLike | None = None
    ) -> NDArray[np.float64]:
        """The exact inverse of ``skin``."""
    def fit_pose(
        self,
        points: ArrayLike,
        targets: ArrayLike,
        weights: ArrayLike | None = None,
        theta0: ArrayLike | None = None,
        huber: float | None = None,
        iterations: int = 50,
    ) -> NDArray[np.float64]:
        """The pose (3,) whose skinning carries ``points`` (N, 3) onto ``targets`` (N, 3), by
        Gauss-Newton from ``theta0`` (None: rest); ``weights`` (N,) are the points' jaw weights
        (None: 1, a rigid fit); ``huber`` (e.g. 1.345) reweighs outliers (IRLS)."""
    def unskin_displacements(
        self, neutral: ArrayLike, displacements: ArrayLike, theta: ArrayLike
    ) -> NDArray[np.float64]:
        """s* = T_v(theta)^-1 (x0 + s) - x0 for one (V, 3) shape displacement."""
    def bundle_weights(
        self, triangles: ArrayLike, bundle_triangles: ArrayLike, barycentrics: ArrayLike
    ) -> NDArray[np.float64]:
        """(B,) jaw weight of each bundle: its triangle's vertex weights blended, clipped."""
    def to_dict(self) -> dict[str, NDArray[np.float64]]:
        """Arrays for ``np.savez``: ``jaw_pivot``, ``jaw_weights``, ``jaw_frame``."""
    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> JawRig:
        """Inverse of ``to_dict`` (accepts a loaded ``.npz``); ``jaw_frame`` is optional."""

@final
class Choices:
    """Per frame and bundle: the local geometry each bundle chose."""

    def __new__(
        cls,
        shapes: NDArray[np.int64],
        weights: NDArray[np.float64],
        tets: NDArray[np.int64],
        projected: NDArray[np.bool_],
        fit: NDArray[np.bool_] | None = None,
    ) -> Choices: ...
    @property
    def shapes(self) -> NDArray[np.int64]:
        """(F, B, 4) dataset shape indices; -1 is the neutral (or an unused slot)."""
    @property
    def weights(self) -> NDArray[np.float64]:
        """(F, B, 4) convex weights of `shapes` (all 0 for a missing bundle)."""
    @property
    def tets(self) -> NDArray[np.int64]:
        """(F, B) tet index in the bundle's index, -1 when none was used."""
    @property
    def projected(self) -> NDArray[np.bool_]:
        """(F, B) True when the marker was outside every tet and was projected."""
    @property
    def fit(self) -> NDArray[np.bool_] | None:
        """(F, B) True where the bundle took the frame's global blendshape fit instead of a tet
        (its `shapes`/`weights` are then unused; the fit is `SolveResult.fit_weights`)."""
    @property
    def inside(self) -> NDArray[np.bool_]:
        """(F, B) True when the marker was inside a tet (interpolated exactly)."""
    def __reduce__(
        self,
    ) -> tuple[
        type[Choices],
        tuple[
            NDArray[np.int64],
            NDArray[np.float64],
            NDArray[np.int64],
            NDArray[np.bool_],
            NDArray[np.bool_] | None,
        ],
    ]: ...

@final
class SolveResult:
    """Output of `Model.solve`."""

    def __new__(
        cls,
        vertices: NDArray[np.float64],
        bundle_residuals: NDArray[np.float64],
        bundle_positions: NDArray[np.float64],
        missing: NDArray[np.bool_],
        choices: Choices,
        jaw_theta: NDArray[np.float64] | None = None,
        jaw_bin: NDArray[np.int64] | None = None,
        marker_corrections: NDArray[np.float64] | None = None,
        fit_weights: NDArray[np.float64] | None = None,
        state: SolveState | None = None,
        filled: NDArray[np.bool_] | None = None,
        repaired: NDArray[np.bool_] | None = None,
        repairs: tuple[Any, ...] | None = None,
        fill_rank: int | None = None,
        marker_pulls: NDArray[np.float64] | None = None,
    ) -> SolveResult: ...
    @property
    def vertices(self) -> NDArray[np.float64]:
        """(F, V, 3) reconstructed meshes."""
    @property
    def bundle_residuals(self) -> NDArray[np.float64]:
        """(F, B) distance from each marker to the reconstructed surface (0 where missing)."""
    @property
    def bundle_positions(self) -> NDArray[np.float64]:
        """(F, B, 3) the markers' surface positions on the result (estimates where missing)."""
    @property
    def missing(self) -> NDArray[np.bool_]:
        """(F, B) markers that were NaN in the input."""
    @property
    def choices(self) -> Choices: ...
    @property
    def jaw_theta(self) -> NDArray[np.float64] | None:
        """(F, 3) jaw poses used (open, lateral, forward), None when solved without a jaw."""
    @property
    def jaw_bin(self) -> NDArray[np.int64] | None:
        """(F,) jaw-opening bin each frame was looked up in (0 for an unbinned jaw model), None
        when solved without a jaw."""
    @property
    def marker_corrections(self) -> NDArray[np.float64] | None:
        """(F, B) how far noise-aware solving (`marker_noise=`) moved each marker before the
        surface interpolated it (data units; 0 when exact)."""
    @property
    def fit_weights(self) -> NDArray[np.float64] | None:
        """(F, S) each frame's global blendshape fit; None when no fit was made (`fit` off, or a
        dataset without shapes)."""
    @property
    def state(self) -> SolveState | None:
        """What the chunk after a temporal solve needs to continue it (`solve_iter` passes it
        on); None for no frames, and after unpickling (a pickled result keeps its arrays)."""
    @property
    def filled(self) -> NDArray[np.bool_] | None:
        """(F, B) missing samples the solve filled from the take (`lgi.solve.gaps`; still
        `missing`); None when the frames were solved each alone."""
    @property
    def repaired(self) -> NDArray[np.bool_] | None:
        """(F, B) samples a repair changed (`lgi.solve.repair`); None when no repair was made."""
    @property
    def repairs(self) -> tuple[Any, ...] | None:
        """The marker faults repaired before the solve (`lgi.solve.diagnose.Finding`s); None
        when the solve did not look for them (`repair=False`, frames solved each alone)."""
    @property
    def fill_rank(self) -> int | None:
        """How many directions of the take's own motion filled its dropouts
        (`lgi.solve.gaps.fill_motion`); None where each marker's neighbours filled them, or
        nothing was filled (`filled` None or all False)."""
    @property
    def marker_pulls(self) -> NDArray[np.float64] | None:
        """(F, B, 3) how far a steady solve moved its surface at each marker to follow it where
        the marker is more than 5 sigma from where the solve put it (`lgi.solve.steady`): the
        surface's markers are `bundle_positions + marker_pulls`; None where it did not."""
    def __reduce__(self) -> tuple[type[SolveResult], tuple[object, ...]]: ...

@final
class SolveState:
    """The last frame's choices and jaw bin of a temporal solve (opaque): the next chunk's
    ``previous``."""

# The dicts the inspection methods return, key by key (they exist only in this stub).
class _BundleStats(TypedDict):
    points: NDArray[np.int64]
    tets: NDArray[np.int64]
    index_bytes: NDArray[np.int64]

class _SewWeights(TypedDict):
    indptr: NDArray[np.int64]
    indices: NDArray[np.int64]
    data: NDArray[np.float64]

class _SurfacePoints(TypedDict):
    triangles: NDArray[np.int64]
    barycentrics: NDArray[np.float64]

class _JawSetup(TypedDict):
    shape_theta: NDArray[np.float64]
    bundle_weights: NDArray[np.float64]
    bin_edges: NotRequired[NDArray[np.float64]]
    bin_overlap: NotRequired[float]
    bin_members: NotRequired[list[list[int]]]

@final
class Model:
    """A built LGI model (immutable, thread-safe). Use ``lgi.Model``, which wraps this."""

    @staticmethod
    def build(
        dataset: Dataset,
        markers_rest: ArrayLike,
        config: BuildConfig | None = None,
        jaw_pivot: ArrayLike | None = None,
        jaw_weights: ArrayLike | None = None,
        shape_theta: ArrayLike | None = None,
        jaw_bins: ArrayLike | None = None,
        bin_overlap: float = 0.0,
        jaw_frame: ArrayLike | None = None,
        marker_names: Sequence[str] | None = None,
        units: str | None = None,
    ) -> Model:
        """Builds a model (``config`` None: the defaults); ``jaw_bins`` are bin
        edges over the jaw opening (radians); ``jaw_frame`` (3, 3) is the jaw rig's rotation
        (columns: open, lateral, forward axes; None: identity); ``marker_names`` (B unique
        names; None: ``m000``…) and ``units`` (e.g. ``cm``; None: unknown) are kept."""
    @staticmethod
    def load(path: _Path) -> Model:
        """Loads a model written by ``save``."""
    def save(self, path: _Path) -> None:
        """Writes the model (versioned binary file)."""
    def to_bytes(self) -> bytes:
        """The bytes ``save`` writes."""
    @staticmethod
    def from_bytes(data: bytes | bytearray) -> Model:
        """A model from ``to_bytes`` (checked like ``load``)."""
    def __reduce__(self) -> tuple[Callable[[bytes], Model], tuple[bytes]]: ...
    @property
    def num_bundles(self) -> int: ...
    @property
    def num_vertices(self) -> int: ...
    @property
    def diagonal(self) -> float: ...
    @property
    def dataset(self) -> Dataset: ...
    @property
    def markers_rest(self) -> NDArray[np.float64]: ...
    @property
    def marker_names(self) -> list[str]:
        """Each marker's name (B); ``m000``, ``m001``, … when built without names."""
    @property
    def units(self) -> str | None:
        """The coordinates' length unit given at build; None when not given."""
    @property
    def jaw_rig(self) -> JawRig | None: ...
    @property
    def config(self) -> BuildConfig: ...
    def solve(
        self,
        frames: ArrayLike,
        progress: Callable[[int], object] | None = None,
        temporal: bool = True,
        jaw: str | ArrayLike | None = None,
        smooth_window: int = 0,
        out: NDArray[np.float64] | None = None,
        fit: bool | None = None,
        marker_noise: float | None = None,
        previous: SolveState | None = None,
        unbounded_fit: bool = False,
        take_prior: tuple[ArrayLike, ArrayLike, float] | None = None,
        surface: Literal["mesh", "markers", "none"] | None = None,
    ) -> SolveResult:
        """Solves (F, B, 3) frames (vertices into `out` if given); ``jaw`` is ``"auto"``,
        ``"fit"``, ``"track"``, (F, 3) poses or None (rest); ``fit`` offers the global fit as a
        candidate (None: exactly when ``marker_noise`` is given), ``marker_noise`` (data units)
        solves noise-aware, ``previous`` (a temporal solve's ``state``) continues that solve,
        ``unbounded_fit`` fits the frame's weights without the [0, 1] box (at the pose the
        boxed fit refined), ``take_prior`` ``(mean, factor, noise_variance)`` puts the take's
        prior on that fit in place of its ridge; ``surface``: ``"mesh"`` (every vertex; None too),
        ``"markers"`` (the markers' positions on the sewn surfaces, the same bits, no vertex
        written) or ``"none"`` (no choice, no sewing: targets, fits and poses; each present
        marker's choice reported as a fit), the last two with ``vertices`` ``out`` as given
        or an empty (F, 0, 3) array."""
    def fit_residuals(
        self, frames: ArrayLike, jaw: str | ArrayLike | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Each frame's global-fit residual (F, B, 3; NaN where missing) and the fit's rank
        at the bundles (F,)."""
    def fit_rows(
        self, frames: ArrayLike, jaw: str | ArrayLike | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Jaw bin 0's fit matrix (3B, S), each frame's markers in its bin's space less the
        bundles' rest (F, 3B; NaN where missing) and each frame's bin (F,)."""
    def bundle_positions(self, meshes: ArrayLike) -> NDArray[np.float64]:
        """(F, V, 3) meshes -> (F, B, 3) bundle surface positions."""
    def bundle_stats(self) -> _BundleStats:
        """Per bundle: ``points``, ``tets``, ``index_bytes``."""
    def sew_weights(self) -> _SewWeights:
        """CSR sewing weights: ``indptr``, ``indices``, ``data``."""
    def neighbours(self) -> list[list[int]]:
        """Natural neighbours of each bundle."""
    def bundle_surface_points(self) -> _SurfacePoints:
        """``triangles`` (B,) and ``barycentrics`` (B, 3)."""
    def jaw(self) -> _JawSetup | None:
        """``shape_theta``, ``bundle_weights`` and, for a binned model, ``bin_edges``,
        ``bin_overlap``, ``bin_members`` (dataset shapes per bin); None without a jaw (the rig
        itself is ``jaw_rig``)."""
    def bundle_uvs(self) -> NDArray[np.float64]:
        """(B, 2) bundle positions in UV."""

@final
class RbfInterpolator:
    """Biharmonic RBF (phi(r) = r, linear polynomial) interpolation of marker values over points;
    marker i's constraint is sum_j sample_weights[i, j] f(points[sample_vertices[i, j]])."""

    def __new__(
        cls, points: ArrayLike, sample_vertices: ArrayLike, sample_weights: ArrayLike
    ) -> RbfInterpolator: ...
    @staticmethod
    def from_dataset(
        dataset: Dataset, markers_rest: ArrayLike, tolerance: float
    ) -> RbfInterpolator:
        """Markers at their closest neutral surface points (within ``tolerance``)."""
    @property
    def num_markers(self) -> int: ...
    @property
    def num_points(self) -> int: ...
    @property
    def matrix(self) -> NDArray[np.float64]:
        """(V, B) interpolation matrix (all markers present)."""
    @property
    def sample_vertices(self) -> NDArray[np.int64]: ...
    @property
    def sample_weights(self) -> NDArray[np.float64]: ...
    @property
    def centres(self) -> NDArray[np.float64]: ...
    def interpolate(self, values: ArrayLike) -> NDArray[np.float64]:
        """(F, B, 3) values (NaN rows missing) -> (F, V, 3)."""

@final
class LocalFits:
    """Each bundle's box-penalised blendshape fit of the markers in its Gaussian window
    (`lgi.plan.local`)."""

    def __new__(
        cls, a: ArrayLike, rest: ArrayLike, l2: float, penalty: float, lengths: float = ...
    ) -> LocalFits:
        """`lengths`: the windows' Gaussian length in median marker spacings (`LOCAL_LENGTH`)."""
    @property
    def num_bundles(self) -> int: ...
    @property
    def num_shapes(self) -> int: ...
    @property
    def window_sizes(self) -> NDArray[np.int64]:
        """How many markers each bundle's window holds (B,)."""
    def solve(self, targets: ArrayLike, starts: ArrayLike) -> tuple[NDArray[np.float64], int]:
        """(F, B, 3) displacements (NaN rows missing) and (F, S) starts -> weights (F, B, S) and
        how many fits kept their start."""

@final
class LocalSurface:
    """The local fits' surface of a chunk of frames in one call (`lgi.solve.local`): blend,
    jaw pose, biharmonic corrective and the markers' positions, frames in parallel."""

    def __new__(
        cls,
        neutral: ArrayLike,
        shapes: NDArray[np.float32],
        indptr: NDArray[np.int64],
        indices: NDArray[np.int64],
        data: NDArray[np.float64],
        rig: JawRig | None,
        corrective: RbfInterpolator,
        model: Model,
    ) -> LocalSurface: ...
    def surface(
        self,
        weights: ArrayLike,
        targets: ArrayLike,
        out: NDArray[np.float64],
        theta: ArrayLike | None = None,
        corrective: bool = True,
    ) -> NDArray[np.float64]:
        """Weights (F, B, q), targets (F, B, 3), `out` (F, V, 3) receiving the surface, jaw
        poses (F, 3) -> the markers' positions on it (F, B, 3). `corrective=False`: the posed
        blend alone (without the corrective through the targets) and the positions on it."""

@final
class BlendshapeSolver:
    """Active-set solver of min |A w - t|^2 + l2 |w|^2 + penalty * box violation^2."""

    def __new__(cls, a: ArrayLike, l2: float, penalty: float) -> BlendshapeSolver: ...
    @property
    def num_shapes(self) -> int: ...
    @property
    def num_rows(self) -> int: ...
    def objective(self, w: ArrayLike, target: ArrayLike) -> float: ...
    def solve(self, targets: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """(F, R) targets (NaN entries dropped) -> weights (F, S), iterations (F,)."""
