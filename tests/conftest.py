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
