"""How a take was solved, kept with what was written (`SolveSettings`): the marker noise, the
jaw pose, the detail weight, whether local fits made the pieces and whether the global fit was
held to [0, 1], as `lgi solve` used them,
and lgi's version. A solved `.npz` holds it as
the JSON text `solve_settings`, a USD cache as the mesh's `lgi:solveSettings`; `lgi report`
and `lgi info` show it, so a result says how it was made without its command line."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

from lgi.errors import InputError

if TYPE_CHECKING:
    from lgi.plan.denoise import DenoisedTake

__all__ = ["LOCAL_FITS_WORDS", "SolveSettings"]

#: How a solve's `local_fits` reads at the end of a line that describes it.
LOCAL_FITS_WORDS: dict[bool | str, str] = {
    False: "",
    True: ", local fits",
    "unbounded": ", unbounded local fits",
}


@dataclass(frozen=True)
class SolveSettings:
    """`marker_noise`: sigma per coordinate in the model's units (None: the exact
    interpolation); `jaw`: the jaw pose mode ('fit', 'track', ...; None without a jaw rig);
    `detail_weight`: the weight in [0, 1] (None: all of the dataset's detail); `version`:
    lgi's version that solved; `local_fits`: the pieces were local fits (`lgi.plan.local`; True,
    or 'unbounded' for `lgi.solve.local.UNBOUNDED` ones; files written before it was
    recorded read as False); `unbounded_fit`: the frame's global fit was not held to [0, 1]
    (`Model.solve(fit="unbounded")`, and always with unbounded local fits; files written
    before it was recorded read as False); `take_prior`: that fit took the take's own prior
    (`lgi.estimate_take_prior`; older files read as False); `denoised_from`: the markers'
    noise before the take was denoised (`lgi.denoise_take`; `marker_noise` is then the noise
    it left) and `denoised_rank` the directions of motion it kept (None: not denoised, as
    older files read); `repairs`: the marker faults repaired before the solve (`lgi.review.
    repair`), each `{"kind", "markers", "first", "last"}` with frames 0-based in the solve
    (a swap undone; a spike or a marker off its track solved as missing; none in older
    files); `steady`: dropouts filled from the take and the detail averaged over neighbouring
    frames (`lgi.solve.steady`; files written before it read as False, as they were solved);
    `dropout_fill`: how the steady solve filled the take's missing samples, 'motion' (the take's
    own motion, `lgi.solve.gaps.fill_motion`, of `fill_rank` directions) or 'neighbours' (each
    marker's neighbours), None where nothing was filled (and in files written before it was
    recorded)."""

    marker_noise: float | None
    jaw: str | None
    detail_weight: float | None
    version: str
    local_fits: bool | str = False
    unbounded_fit: bool = False
    take_prior: bool = False
    denoised_from: float | None = None
    denoised_rank: int | None = None
    repairs: tuple[tuple[str, tuple[str, ...], int, int], ...] = ()
    steady: bool = False
    dropout_fill: str | None = None
    fill_rank: int | None = None

    @staticmethod
    def of(
        *,
        has_jaw_rig: bool,
        jaw: object,
        marker_noise: float | None,
        detail_weight: float | None,
        local_fits: bool | str = False,
        unbounded_fit: bool = False,
        take_prior: bool = False,
        denoised: DenoisedTake | None = None,
        steady: bool = False,
    ) -> SolveSettings:
        """The settings of a `Model.solve` call: `jaw` as passed (None, the rest pose, is
        recorded as 'rest' and a pose array as 'given'; None for a model without a jaw rig),
        `denoised` the take `lgi.denoise_take` made of the given one (its noise and rank),
        this lgi's version."""
        from lgi._lgi import __version__

        if not has_jaw_rig:
            mode = None
        elif jaw is None:
            mode = "rest"
        else:
            mode = jaw if isinstance(jaw, str) else "given"
        return SolveSettings(
            marker_noise=None if marker_noise is None else float(marker_noise),
            jaw=mode,
            detail_weight=None if detail_weight is None else float(detail_weight),
            version=__version__,
            local_fits=local_fits if local_fits == "unbounded" else bool(local_fits),
            unbounded_fit=bool(unbounded_fit) or local_fits == "unbounded",
            take_prior=bool(take_prior),
            denoised_from=None if denoised is None else float(denoised.input_noise),
            denoised_rank=None if denoised is None else int(denoised.rank),
            steady=bool(steady),
        )

    def with_fill(self, filled: bool, rank: int | None) -> SolveSettings:
        """These settings with how the solve filled the take's dropouts: `filled`, whether it
        filled any sample; `rank`, the directions of the take's motion that filled them (None:
        each marker's neighbours did; `SolveResult.fill_rank`)."""
        if not filled:
            return replace(self, dropout_fill=None, fill_rank=None)
        return replace(
            self, dropout_fill="neighbours" if rank is None else "motion", fill_rank=rank
        )

    @property
    def given_noise(self) -> float | None:
        """The noise of the markers the user gave (the residuals written are theirs): the
        noise before denoising where the take was denoised, else `marker_noise`."""
        return self.marker_noise if self.denoised_from is None else self.denoised_from

    def to_json(self) -> str:
        return json.dumps(
            {
                "marker_noise": self.marker_noise,
                "jaw": self.jaw,
                "detail_weight": self.detail_weight,
                "version": self.version,
                "local_fits": self.local_fits,
                "unbounded_fit": self.unbounded_fit,
                "take_prior": self.take_prior,
                "denoised_from": self.denoised_from,
                "denoised_rank": self.denoised_rank,
                "steady": self.steady,
                "dropout_fill": self.dropout_fill,
                "fill_rank": self.fill_rank,
                "repairs": [
                    {"kind": k, "markers": list(m), "first": a, "last": b}
                    for k, m, a, b in self.repairs
                ],
            },
            sort_keys=True,
        )

    @staticmethod
    def from_json(text: str, where: str) -> SolveSettings:
        """The settings of `text`; `InputError` naming `where` (file and key) for anything but
        what `to_json` writes."""
        try:
            d: Any = json.loads(text)
        except ValueError:
            raise InputError(f"{where}: not the JSON text lgi writes: {text[:60]!r}") from None
        keys = {"marker_noise", "jaw", "detail_weight", "version"}
        optional = {
            "local_fits",
            "unbounded_fit",
            "take_prior",
            "denoised_from",
            "denoised_rank",
            "repairs",
            "steady",
            "dropout_fill",
            "fill_rank",
        }
        if not isinstance(d, dict) or not keys <= set(d) <= keys | optional:
            raise InputError(
                f"{where}: expected the keys marker_noise, jaw, detail_weight, version and "
                "(optionally) local_fits, unbounded_fit, take_prior, denoised_from, "
                "denoised_rank, repairs, steady, dropout_fill and fill_rank"
            )
        local = d.get("local_fits", False)
        if not isinstance(local, bool) and local != "unbounded":
            raise InputError(
                f"{where}: local_fits must be true, false or 'unbounded', got {local!r}"
            )
        unbounded = d.get("unbounded_fit", False)
        if not isinstance(unbounded, bool):
            raise InputError(f"{where}: unbounded_fit must be true or false, got {unbounded!r}")
        steady = d.get("steady", False)
        if not isinstance(steady, bool):
            raise InputError(f"{where}: steady must be true or false, got {steady!r}")
        prior = d.get("take_prior", False)
        if not isinstance(prior, bool):
            raise InputError(f"{where}: take_prior must be true or false, got {prior!r}")

        def number(key: str) -> float | None:
            x = d[key]
            if x is None:
                return None
            if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
                raise InputError(f"{where}: {key} must be a finite number or null, got {x!r}")
            return float(x)

        rank = d.get("denoised_rank")
        if rank is not None and (isinstance(rank, bool) or not isinstance(rank, int) or rank < 0):
            raise InputError(
                f"{where}: denoised_rank must be a whole number >= 0 or null, got {rank!r}"
            )
        fill, fill_rank = d.get("dropout_fill"), d.get("fill_rank")
        whole = isinstance(fill_rank, int) and not isinstance(fill_rank, bool) and fill_rank >= 1
        if (fill, fill_rank is None) not in ((None, True), ("neighbours", True)) and not (
            fill == "motion" and whole
        ):
            raise InputError(
                f"{where}: dropout_fill must be 'motion' with a fill_rank >= 1, 'neighbours' or "
                f"null (without a fill_rank), got {fill!r} and {fill_rank!r}"
            )
        repairs = []
        items: list[Any] = d.get("repairs", [])
        for item in items if isinstance(items, list) else [items]:
            ok = (
                isinstance(item, dict)
                and set(item) == {"kind", "markers", "first", "last"}
                and item["kind"] in ("swap", "spike", "off")
                and isinstance(item["markers"], list)
                and all(isinstance(n, str) for n in item["markers"])
                and all(
                    isinstance(item[k], int) and not isinstance(item[k], bool) and item[k] >= 0
                    for k in ("first", "last")
                )
            )
            if not ok:
                raise InputError(
                    f"{where}: repairs must be a list of {{kind, markers, first, last}}, got "
                    f"{item!r}"
                )
            assert isinstance(item, dict)
            repairs.append((item["kind"], tuple(item["markers"]), item["first"], item["last"]))
        for key in ("jaw", "version"):
            if d[key] is not None and not isinstance(d[key], str):
                raise InputError(f"{where}: {key} must be text or null, got {d[key]!r}")
        return SolveSettings(
            marker_noise=number("marker_noise"),
            jaw=d["jaw"],
            detail_weight=number("detail_weight"),
            version=str(d["version"] or ""),
            local_fits=local,
            unbounded_fit=unbounded,
            take_prior=prior,
            denoised_from=number("denoised_from") if "denoised_from" in d else None,
            denoised_rank=rank,
            repairs=tuple(repairs),
            steady=steady,
            dropout_fill=fill,
            fill_rank=fill_rank,
        )

    def describe(self, units: str | None, start: int = 0) -> str:
        """One line, e.g. 'marker noise 0.05 cm, jaw pose from the fit, detail weight 0.470
        (lgi 0.1.0)'; repairs at time codes from `start`, the solve's first."""
        unit = f" {units}" if units else ""
        noise = (
            "no marker noise (every marker interpolated as given)"
            if self.marker_noise is None
            else f"marker noise {self.marker_noise:.4g}{unit} per coordinate"
        )
        if self.denoised_from is not None:
            noise += (
                f" (the take denoised from {self.denoised_from:.4g}{unit}, "
                f"{self.denoised_rank} directions of motion kept)"
            )
        jaw = "no jaw rig" if self.jaw is None else f"jaw pose '{self.jaw}'"
        detail = (
            "all of the dataset's detail"
            if self.detail_weight is None
            else f"detail weight {self.detail_weight:.3f}"
        )
        frames = ", each frame alone"
        if self.steady:
            fill = self.fill_words()
            frames = (
                ", dropouts filled and detail steady over frames"
                if fill is None
                else f", dropouts filled {fill}, detail steady over frames"
            )
        version = self.version or "version unknown"
        line = f"{noise}, {jaw}, {detail}{self.pieces()}{frames} (lgi {version})"
        return line + "".join(f"; repaired: {r}" for r in self.repair_lines(start))

    def fill_words(self) -> str | None:
        """How the dropouts were filled, e.g. "from the take's own motion (4 directions)";
        None where nothing was filled (or it was not recorded)."""
        if self.dropout_fill == "motion":
            return f"from the take's own motion ({self.fill_rank} directions)"
        if self.dropout_fill == "neighbours":
            return "from each marker's neighbours"
        return None

    def repair_lines(self, start: int = 0) -> list[str]:
        """Each repair in a few words, frames as time codes from `start`: 'm063 <-> m153
        swapped, time codes 301-360', 'm029 solved as missing (a spike), time code 206'."""
        out = []
        for kind, markers, first, last in self.repairs:
            span = (
                f"time code {start + first}"
                if first == last
                else f"time codes {start + first}-{start + last}"
            )
            if kind == "swap":
                out.append(f"{markers[0]} <-> {markers[1]} swapped, {span}")
            else:
                what = "a spike" if kind == "spike" else "off its track"
                out.append(f"{markers[0]} solved as missing ({what}), {span}")
        return out

    def pieces(self) -> str:
        """How the pieces and the global fit read at the end of a line that describes the solve:
        '', ', local fits', ', unbounded fit' or ', unbounded local fits' (which start from the
        unbounded fit), then ', take prior' where that fit took the take's prior."""
        prior = ", take prior" if self.take_prior else ""
        if self.unbounded_fit and self.local_fits != "unbounded":
            return LOCAL_FITS_WORDS[self.local_fits] + ", unbounded fit" + prior
        return LOCAL_FITS_WORDS[self.local_fits] + prior
