"""Whether a take gains by local fits (`lgi.solve.local`), read from its own markers left out:
`estimate_local_fits` solves the left-out rows with and without them, bounded and unbounded,
and keeps them only where they save left-out distance significantly."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lgi.errors import InputError
from lgi.plan.detail import DETAIL_FRAMES
from lgi.plan.leave_out import LEFT_OUT_PER_FRAME, LOOK_SIGNIFICANCE, LOOKS, Looks
from lgi.plan.readings import TakeReadings
from lgi.solve.local import UNBOUNDED, local_pieces

if TYPE_CHECKING:
    from lgi.solve.model import Model

F64 = NDArray[np.float64]

__all__ = ["LocalFitsEstimate", "estimate_local_fits"]


@dataclass(frozen=True)
class LocalFitsEstimate:
    """Whether local fits predict a take's left-out markers better (`estimate_local_fits`)."""

    use: bool
    """Local fits saved left-out distance by more than `LOOK_SIGNIFICANCE` standard errors at
    one of the looks."""
    error_without: float
    """Mean distance (data units) of the left-out markers from the recommended solve's surface
    without them."""
    error_with: float
    """The same with local fits (held to [0, 1]; NaN where only unbounded ones were read)."""
    left_out: int
    """Markers left out (one per solved frame)."""
    frames: int
    """Take frames they were left out of (`frames_used` a look)."""
    unbounded: bool = False
    """The local fits used are `UNBOUNDED` ones (bounded ones saved significantly, and these
    saved more, significantly too)."""
    error_unbounded: float = float("nan")
    """The left-out distance with unbounded local fits (and the unbounded global fit); NaN
    where bounded ones did not save (not read)."""

    @property
    def local_fits(self) -> bool | str:
        """What to pass as `Model.solve(local_fits=...)`: False, True or `UNBOUNDED`."""
        if not self.use:
            return False
        return UNBOUNDED if self.unbounded else True


def estimate_local_fits(
    frames: ArrayLike,
    model: Model,
    *,
    marker_noise: float,
    jaw: str | None = "auto",
    frames_used: int = DETAIL_FRAMES,
    fit: bool | str | None = None,
    readings: TakeReadings | None = None,
) -> LocalFitsEstimate:
    """Whether local fits suit a take (F, B, 3; NaN rows missing) and `model`, and which kind,
    read from the take's own markers: on `frames_used` frames spread over the take, up to
    `LEFT_OUT_PER_FRAME` present markers each are left out in turn, predicted by the solve with
    `marker_noise` and `jaw` without them, and by the same solve with bounded local fits.
    They are used when the left-out distance they save, averaged per frame, exceeds
    `LOOK_SIGNIFICANCE` standard errors of that mean over the frames read; then the same rows
    are solved with `UNBOUNDED` local fits (and the unbounded global fit they start from), used
    instead if they save more and their saving clears the same boundary (a fixed sequence of two
    tests: neither kind is chosen by chance more often than one). When bounded ones do not
    clear it and their saving is positive, `frames_used` more frames are read, up to `LOOKS`
    looks (a clear case costs one look, a close one up to three). With the performer's own
    scans they usually save it; with a generic dataset driven by another face they usually
    cost it (docs/results.md). Each look solves about `frames_used` x 30 frames, with their
    local fits (not their meshes); reading unbounded ones solves those rows once more.
    `fit=UNBOUNDED` (the take is solved with the unbounded global fit, `Model.solve(fit=...)`):
    the solve without local fits is that one, and only unbounded local fits are read (one test
    at the same boundary). `readings`: the take's readings to share rows and solves with (made
    for this call where not given)."""
    if marker_noise is None:
        raise InputError("estimate_local_fits needs marker_noise (0 for clean markers)")
    if frames_used < 1:
        raise InputError(f"frames_used must be >= 1, got {frames_used}")
    only_unbounded = fit == UNBOUNDED
    if not (only_unbounded or fit is None or fit is True):
        raise InputError(f"fit: expected None, True or {UNBOUNDED!r}, got {fit!r}")
    r = TakeReadings.given(readings, frames, model, marker_noise=marker_noise, jaw=jaw)
    key = (LOOKS * frames_used, LEFT_OUT_PER_FRAME)
    out = r.left_out(*key, what="local fits")
    looks = Looks(out)
    pieces = local_pieces(model)
    err_without = np.full(out.marker.size, np.nan)
    # Left-out distances with local fits: bounded (column 0) and unbounded (column 1, read only
    # once bounded ones have saved: the second test of the sequence).
    err_with = np.full((out.marker.size, 2), np.nan)

    def distances(rows: NDArray[np.int64], kind: int, base: bool) -> None:
        """The left-out distances of `rows` with local fits of `kind` (column of `err_with`:
        0 bounded, 1 unbounded, on the solve with the unbounded global fit); with `base`, the
        solve's own (without them) too."""
        solved = r.solved(*key, rows, fit=UNBOUNDED if kind else None)
        if base:
            err_without[rows] = looks.distances(rows, solved.bundle_positions)
        on = pieces.at_bundles(solved, bounded=kind == 0)
        err_with[rows, kind] = looks.distances(rows, on)

    first = 1 if only_unbounded else 0
    look = looks.first_clearing(
        lambda rows: distances(rows, first, True), err_without, err_with[:, first]
    )
    use = look is not None
    unbounded = use and only_unbounded
    if look is not None and not only_unbounded:
        # A fixed sequence: bounded local fits first (the FACS rig's prior, the cautious kind),
        # unbounded ones (with the unbounded global fit they start from) only after them, on
        # the same rows, so each test keeps the whole 2.3 %.
        distances(looks.rows(look, through=True), 1, False)
        mean, _, _ = looks.saving(err_without, err_with[:, 0], look)
        mean_u, spread_u, _ = looks.saving(err_without, err_with[:, 1], look)
        unbounded = mean_u > LOOK_SIGNIFICANCE * spread_u and mean_u > mean
    done = np.isfinite(err_without)
    return LocalFitsEstimate(
        use=use,
        error_without=float(err_without[done].mean()),
        error_with=float(err_with[done, 0].mean()),
        left_out=int(done.sum()),
        frames=int(np.unique(out.frame[done]).size),
        unbounded=unbounded,
        error_unbounded=float(err_with[done, 1].mean()) if use or only_unbounded else float("nan"),
    )
