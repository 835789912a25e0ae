"""PC2 and MDD point caches read back by readers written here from the formats' published
layouts (Blender's `io_export_pc2` / Mesh Cache modifier for PC2, LightWave's MDD as Blender's
`io_shape_mdd` reads it), not with the writer's code: the solve to float32, the first frame and
the times kept, whole or absent when interrupted."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from lgi.errors import InputError
from lgi.io.pointcache import PointCache
from lgi.io.result import read_result_npz
from pipeline_files import lgi_cli, spiked_sample_take, write_solve


def read_pc2(path: Path) -> tuple[float, float, np.ndarray]:
    """(start frame, sample rate, (F, V, 3) float32) from a PC2 file."""
    data = path.read_bytes()
    sig, version, points, start, rate, samples = struct.unpack("<12siiffi", data[:32])
    assert sig == b"POINTCACHE2\0" and version == 1
    assert len(data) == 32 + samples * points * 12
    v = np.frombuffer(data, dtype="<f4", offset=32).reshape(samples, points, 3)
    return start, rate, v


def read_mdd(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(times in seconds, (F, V, 3) float32) from an MDD file."""
    data = path.read_bytes()
    frames, points = struct.unpack(">ii", data[:8])
    times = np.frombuffer(data, dtype=">f4", count=frames, offset=8)
    assert len(data) == 8 + 4 * frames + frames * points * 12
    v = np.frombuffer(data, dtype=">f4", offset=8 + 4 * frames).reshape(frames, points, 3)
    return times, v


@pytest.fixture(scope="module")
def solved(sample, sample_model, tmp_path_factory):  # type: ignore[no-untyped-def]
    frames = spiked_sample_take(sample, sample_model)
    return write_solve(tmp_path_factory.mktemp("pc") / "take.npz", sample_model, frames, None)


def test_pc2_written_by_lgi_export_equals_the_solve_to_float32_and_keeps_the_range(
    solved: Path, tmp_path: Path
) -> None:
    r = read_result_npz(solved)
    out = tmp_path / "take.pc2"
    p = lgi_cli("export", solved, "-o", out, "--frames", "10:60", "-q")
    assert p.returncode == 0, p.stderr
    start, rate, v = read_pc2(out)
    assert (start, rate) == (float(r.start + 10), 1.0)
    np.testing.assert_array_equal(v, r.vertices[10:60].astype(np.float32))


def test_mdd_written_by_lgi_export_equals_the_solve_and_times_are_time_codes_over_the_rate(
    solved: Path, tmp_path: Path
) -> None:
    r = read_result_npz(solved)
    out = tmp_path / "take.mdd"
    p = lgi_cli("export", solved, "-o", out, "-q")
    assert p.returncode == 0, p.stderr
    times, v = read_mdd(out)
    np.testing.assert_array_equal(v, r.vertices.astype(np.float32))
    np.testing.assert_allclose(times, (r.start + np.arange(len(v))) / 30.0, rtol=1e-6)


def test_a_cache_written_in_chunks_equals_one_written_at_once(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    v = rng.normal(size=(23, 17, 3))
    for suffix in (".pc2", ".mdd"):
        whole = PointCache(tmp_path / f"a{suffix}", 17, fps=24.0, start=5)
        whole.add(v)
        whole.close()
        parts = PointCache(tmp_path / f"b{suffix}", 17, fps=24.0, start=5)
        for k in range(0, 23, 7):
            parts.add(v[k : k + 7])
        parts.close()
        assert (tmp_path / f"a{suffix}").read_bytes() == (tmp_path / f"b{suffix}").read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.mdd", "a.pc2", "b.mdd", "b.pc2"]


def test_a_discarded_cache_leaves_nothing_and_mdd_needs_a_rate(tmp_path: Path) -> None:
    c = PointCache(tmp_path / "x.mdd", 4, fps=30.0, start=0)
    c.add(np.zeros((3, 4, 3)))
    c.discard()
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(InputError, match="its frame times need a rate"):
        PointCache(tmp_path / "y.mdd", 4, fps=None, start=0)
    with pytest.raises(InputError, match=r"frames must be \(F, 4, 3\)"):
        PointCache(tmp_path / "z.pc2", 4, fps=None, start=0).add(np.zeros((2, 5, 3)))
    assert list(tmp_path.iterdir()) == []  # the failed cache removed its temporary
