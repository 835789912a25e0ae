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

ICT_SKIN = 9409  # face skin is vertices 0..9408 (../shared/data/README.md)


def shared_data() -> Path:
    env = os.environ.get("LGI_SHARED_DATA")
    if env:
        return Path(env)
    return Path(__file__).resolve().parents[2] / "shared" / "data"


def ict_dir() -> Path:
    d = shared_data() / "ict-facekit"
    if not (d / "generic_neutral_mesh.obj").is_file():
        pytest.skip(f"ICT-FaceKit data not found at {d} (set LGI_SHARED_DATA to its parent)")
    return d


@pytest.fixture(scope="session")
def ict_path() -> Path:
    return ict_dir()


@pytest.fixture(scope="session")
def ict_dataset(ict_path: Path):  # type: ignore[no-untyped-def]
    import lgi

    return lgi.Dataset.from_obj(
        ict_path / "generic_neutral_mesh.obj", str(ict_path / "shapes" / "*.obj")
    )


@pytest.fixture(scope="session")
def ict_markers(ict_path: Path) -> np.ndarray:
    return np.loadtxt(ict_path / "markers_120.csv", delimiter=",", skiprows=1, usecols=(1, 2, 3))


@pytest.fixture(scope="session")
def ict_model(ict_dataset, ict_markers):  # type: ignore[no-untyped-def]
    import lgi

    return lgi.Model.build(ict_dataset, ict_markers)


@pytest.fixture(scope="session")
def sample():  # type: ignore[no-untyped-def]
    from lgi.sample import make_sample

    return make_sample(0)


@pytest.fixture(scope="session")
def sample_dataset(sample):  # type: ignore[no-untyped-def]
    from lgi.dataset import sample_dataset as of_sample

    return of_sample(sample)


@pytest.fixture(scope="session")
def sample_model(sample, sample_dataset):  # type: ignore[no-untyped-def]
    import lgi

    return lgi.Model.build(sample_dataset, sample.markers_rest)
