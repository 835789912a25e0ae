"""The headless error panel: a PNG of the expected size with real content, and the demo's
comparison outputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lgi.lab.render import panel


def test_panel_png_has_expected_size_and_nontrivial_content(sample, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    import matplotlib.image as mpimg

    truth = sample.truth[10]
    rng = np.random.default_rng(0)
    moved = truth + rng.normal(scale=0.05, size=truth.shape)
    err = np.linalg.norm(moved - truth, axis=1)
    size = panel(
        tmp_path / "p.png",
        {"ground truth": truth, "noisy": moved},
        sample.triangles,
        {"noisy": err},
        cell_inches=2.0,
        dpi=50,
    )
    # 2 columns of 2 in plus 1 in for the colour bar; 2 rows of 2 in plus 0.4 in of titles.
    assert size == (250, 220)
    img = mpimg.imread(tmp_path / "p.png")
    assert img.shape[:2] == (220, 250)
    rgb = img[..., :3]
    assert (rgb.std(axis=(0, 1)) > 0.05).all()
    assert len(np.unique((rgb * 255).astype(np.uint8).reshape(-1, 3), axis=0)) > 100


def test_demo_writes_comparison_table_and_panel(tmp_path: Path) -> None:
    from lgi.lab import demo

    assert demo.run(tmp_path, quiet=True) == 0
    text = (tmp_path / "results.md").read_text()
    for name in ("displacement interpolation", "blendshape fit", "LGI-RBF", "| LGI |"):
        assert name in text
    assert (tmp_path / "panel.png").stat().st_size > 10_000
    page = (tmp_path / "report.html").read_text()
    assert "Difference to the ground truth" in page and "(cm)" in page


def _yellow_share(rgb: np.ndarray) -> float:
    """Share of pixels near viridis' top (yellow): r, g high, b low."""
    return float(((rgb[..., 0] > 0.75) & (rgb[..., 1] > 0.75) & (rgb[..., 2] < 0.4)).mean())


def test_per_column_scales_make_a_ten_times_smaller_error_readable(sample, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    import matplotlib.image as mpimg

    truth = sample.truth[10]
    err = np.abs(truth[:, 1] - truth[:, 1].min())  # grows from chin to forehead
    meshes = {"small": truth, "large": truth}
    errors = {"small": err / 10, "large": err}
    for per_column in (False, True):
        panel(
            tmp_path / f"{per_column}.png",
            meshes,
            sample.triangles,
            errors,
            cell_inches=2.0,
            dpi=50,
            per_column=per_column,
        )
    shared = mpimg.imread(tmp_path / "False.png")[..., :3]
    own = mpimg.imread(tmp_path / "True.png")[..., :3]
    left = lambda img: img[:, : img.shape[1] // 2]  # noqa: E731 - the "small" column
    # On the shared scale the small errors never reach the top colour; on their own they do.
    assert _yellow_share(left(shared)) < 0.001
    assert _yellow_share(left(own)) > 0.01


def test_an_interrupted_panel_leaves_the_earlier_png_whole_and_no_temporary(
    sample, tmp_path: Path, monkeypatch
) -> None:  # type: ignore[no-untyped-def]
    from matplotlib.figure import Figure

    target = tmp_path / "panel.png"
    target.write_bytes(b"earlier panel")
    truth = sample.truth[10]

    def half_written(self, fname, **kw):  # type: ignore[no-untyped-def]
        with open(fname, "wb") as fh:
            fh.write(b"\x89PNG partial")
        raise KeyboardInterrupt

    monkeypatch.setattr(Figure, "savefig", half_written)
    with pytest.raises(KeyboardInterrupt):
        panel(target, {"t": truth}, sample.triangles, {"t": np.zeros(len(truth))}, dpi=20)
    assert target.read_bytes() == b"earlier panel"
    assert [p.name for p in tmp_path.iterdir()] == ["panel.png"]
