"""Shared fixtures: the ICT-FaceKit data beside the checkout (skipped, saying why, when absent)
and models built from it once per session."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

settings.register_profile("ci", max_examples=60, deadline=None, derandomize=True)
settings.register_profile("dev", max_examples=30, deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


def ict_dir() -> Path:
    from lgi.lab import ict

    d = ict.find(os.environ.get(ict.ENV), start=Path(__file__).parent)
    if d is None:
        pytest.skip(f"ICT-FaceKit data not found (set {ict.ENV} to its parent folder)")
    return d


@pytest.fixture(scope="session")
def ict_path() -> Path:
    return ict_dir()


@pytest.fixture(scope="session")
def ict_dataset(ict_path: Path):  # type: ignore[no-untyped-def]
    from lgi.lab import ict

    return ict.load_dataset(ict_path)


@pytest.fixture(scope="session")
def rom_scans(ict_dataset):  # type: ignore[no-untyped-def]
    """The scans protocol's setting (docs/results.md): a model of 120 whole-face scans picked
    from the shared slate recording on 160 random markers (cm), and what makes takes of the
    other recording for it: (dataset, jaw hinge, ROM curves, markers, model)."""
    import lgi
    from lgi.io.livelink import read_livelinkface
    from lgi.lab import ict
    from lgi.lab.capture import HingeJaw, random_layout
    from lgi.lab.scans import scan_session
    from lgi.solve.jaw import auto_rig

    folder = ict_dir().parent / "livelinkface"
    recordings = [folder / f"{r}.csv" for r in ("alex_rom_4", "jmtechart_myslate_3")]
    if not all(r.is_file() for r in recordings):
        pytest.skip(f"needs the two shared Live Link recordings in {folder}")
    data = ict_dataset
    hinge = HingeJaw.fit(data, ict.lower_teeth())
    rig, theta = auto_rig(data)
    rom, slate = (read_livelinkface(r).for_dataset(data.names) for r in recordings)
    session = scan_session(data, slate, 120, hinge, theta, nonlinear=None)
    markers = random_layout(data, 160, 1, np.arange(ict.NARROW_FACE))
    model = lgi.Model.build(session.dataset, markers, jaw=rig, shape_theta=session.theta)
    return data, hinge, rom, markers, model


@pytest.fixture(scope="session")
def ict_markers(ict_path: Path) -> np.ndarray:
    from lgi.lab import ict

    return ict.load_markers(ict_path)


@pytest.fixture(scope="session")
def ict_model(ict_dataset, ict_markers):  # type: ignore[no-untyped-def]
    """The paper's model of ICT: no jaw rig (`jaw=None`), so its solves are the paper's."""
    import lgi

    return lgi.Model.build(ict_dataset, ict_markers, jaw=None)


@pytest.fixture(scope="session")
def sample():  # type: ignore[no-untyped-def]
    from lgi.lab.sample import make_sample

    return make_sample(0)


@pytest.fixture(scope="session")
def sample_dataset(sample):  # type: ignore[no-untyped-def]
    from lgi.lab.sample import sample_dataset as of_sample

    return of_sample(sample)


@pytest.fixture(scope="session")
def sample_model(sample, sample_dataset):  # type: ignore[no-untyped-def]
    """The paper's model of the sample: no jaw rig (`jaw=None`)."""
    import lgi

    return lgi.Model.build(sample_dataset, sample.markers_rest, jaw=None)


@pytest.fixture(scope="session")
def noise_aware_sample(sample, sample_dataset):  # type: ignore[no-untyped-def]
    """The sample's default build (with its jaw rig) and its performance's marker noise: the
    recommended call's model and sigma."""
    import lgi

    model = lgi.Model.build(sample_dataset, sample.markers_rest)
    return model, lgi.estimate_marker_noise(sample.performance, model)


@pytest.fixture(scope="session")
def outside_the_box():  # type: ignore[no-untyped-def]
    """The sample's model and frames of weights in [-1, 2] on the shapes that do not turn the
    jaw (truth meshes too), one marker missing on one frame: faces a fit held to [0, 1]
    cannot reach (the unbounded fit's and the unbounded peer's tests)."""
    import lgi
    from lgi.lab.sample import make_sample, sample_dataset

    s = make_sample(0)
    data = sample_dataset(s)
    model = lgi.Model.build(data, s.markers_rest)
    theta_s = np.asarray(model.core.jaw()["shape_theta"])
    x0, shapes = np.asarray(data.neutral), np.asarray(data.shapes, dtype=np.float64)
    still = np.abs(theta_s).max(axis=1) == 0.0
    rng = np.random.default_rng(4)
    w = rng.uniform(-1, 2, (6, data.num_shapes)) * (rng.random((6, data.num_shapes)) < 0.2)
    w[:, ~still] = 0.0
    truth = x0[None] + np.einsum("fk,kvd->fvd", w, shapes)
    frames = model.bundle_positions(truth)
    frames[2, 5] = np.nan
    return model, frames, truth
