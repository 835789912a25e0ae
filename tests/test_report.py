"""`lgi report`: the statistics it prints are checked against plain loops, the differences
against closed forms, and the page against what a solve with a planted spike must show."""

from __future__ import annotations

import base64
import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from lgi.errors import InputError
from lgi.io.result import Result, read_result_npz, write_result_npz
from lgi.io.topology import Topology
from lgi.review.report import compare, marker_stats, render_report, surface_jumps
from pipeline_files import lgi_cli, spiked_sample_take, write_solve


def _result(vertices, residuals, missing, names, units="cm", start=0):  # type: ignore[no-untyped-def]
    nv = vertices.shape[1]
    topo = Topology(nv, np.array([3]), np.array([0, 1, 2]), None, None)
    return Result(
        vertices=vertices.astype(np.float32),
        bundle_residuals=residuals,
        missing=missing,
        marker_names=names,
        fps=30.0,
        start=start,
        units=units,
        topology=topo,
    )


def test_surface_jumps_rank_a_planted_one_frame_excursion_first_with_its_size_and_markers() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(300, dtype=float)[:, None, None]
    v = np.broadcast_to(rng.normal(size=(1, 40, 3)), (300, 40, 3)) + 0.01 * t  # steady motion
    v = v.copy()
    v[261, 17] += [0.0, 0.0, 0.4]  # one vertex, one frame (across the 256-frame block edge)
    v[120, 5] += [0.1, 0.0, 0.0]
    markers = np.stack([v[:, 17] + [0.05, 0, 0], v[:, 5], v[:, 30] + [0.2, 0, 0]], axis=1)
    markers[261, 1] = np.nan  # a missing marker is nobody's nearest
    solved = _result(v, np.zeros((300, 3)), np.zeros((300, 3), bool), ["a", "b", "c"], start=10)
    solved = dataclasses.replace(solved, markers=markers.astype(np.float32))
    jumps = surface_jumps(solved, 4)
    assert [j.frame for j in jumps[:2]] == [261, 260] or [j.frame for j in jumps[:2]] == [261, 262]
    # The second difference of a one-frame excursion of 0.4 is 0.8 at its frame, 0.4 beside it.
    assert jumps[0].vertex == 17 and jumps[0].size == pytest.approx(0.8, abs=1e-5)
    assert jumps[0].markers == ["a", "c"]
    assert {j.frame for j in jumps} == {260, 261, 262, 120}
    page = render_report(solved, source="take.npz")
    table = page.split("<h2>Where the surface jumps</h2>")[1].split("</table>")[0]
    assert re.findall(r"<tr id='jump-(\d+)'>", table)[0] == "271"  # time code 10 + 261


def test_marker_stats_equal_a_plain_loop_over_present_samples() -> None:
    rng = np.random.default_rng(3)
    f, b = 57, 6
    res = rng.gamma(2.0, 0.1, (f, b))
    missing = rng.random((f, b)) < 0.2
    missing[10:25, 2] = True  # a 15-frame gap at least
    missing[:, 5] = True  # never seen
    r = _result(np.zeros((f, 3, 3)), res, missing, [f"m{i}" for i in range(b)])
    s = marker_stats(r)
    for k in range(b):
        vals = [res[i, k] for i in range(f) if not missing[i, k]]
        if not vals:
            assert np.isnan(s.median[k]) and s.worst_frame[k] == -1
        else:
            assert s.median[k] == pytest.approx(np.median(vals))
            assert s.max[k] == max(vals)
            assert res[s.worst_frame[k], k] == max(vals) and not missing[s.worst_frame[k], k]
        run = best = 0
        for i in range(f):
            run = run + 1 if missing[i, k] else 0
            best = max(best, run)
        assert s.longest_gap[k] == best
        assert s.missing[k] == pytest.approx(missing[:, k].mean())
    assert s.longest_gap[2] >= 15 and s.longest_gap[5] == f


def test_difference_to_a_uniformly_shifted_solve_is_the_shift_length_everywhere() -> None:
    rng = np.random.default_rng(0)
    v = rng.normal(size=(9, 40, 3))
    a = _result(v, np.zeros((9, 3)), np.zeros((9, 3), bool), ["a", "b", "c"])
    b = _result(
        v + np.array([0.1, 0.2, 0.2]), np.zeros((9, 3)), np.zeros((9, 3), bool), ["a", "b", "c"]
    )
    c = compare(a, b, "shifted")
    np.testing.assert_allclose(c.per_frame_mean, 0.3, rtol=1e-6)
    np.testing.assert_allclose(c.per_frame_max, 0.3, rtol=1e-6)
    np.testing.assert_allclose(c.per_vertex_mean, 0.3, rtol=1e-6)


def test_comparing_solves_of_different_meshes_or_units_is_refused() -> None:
    z = np.zeros((4, 3))
    a = _result(np.zeros((4, 10, 3)), z, z.astype(bool), ["a", "b", "c"])
    with pytest.raises(InputError, match="same mesh and frames"):
        compare(a, _result(np.zeros((4, 11, 3)), z, z.astype(bool), ["a", "b", "c"]), "b")
    with pytest.raises(InputError, match="units are mm"):
        compare(a, _result(np.zeros((4, 10, 3)), z, z.astype(bool), ["a", "b", "c"], "mm"), "b")


@pytest.fixture(scope="module")
def spiked(sample, sample_model, tmp_path_factory):  # type: ignore[no-untyped-def]
    """The spiked sample take (`spiked_sample_take`) solved noise-aware, so the solve
    corrects the spike instead of following it."""
    frames = spiked_sample_take(sample, sample_model)
    return write_solve(tmp_path_factory.mktemp("report") / "spiked.npz", sample_model, frames, 0.02)


def test_report_names_a_planted_spike_by_marker_and_time_code_with_units(spiked: Path) -> None:
    solved = read_result_npz(spiked)
    page = render_report(solved, source=str(spiked))
    worst_markers = page.split("<h2>Worst markers</h2>")[1].split("</table>")[0]
    rows = re.findall(r"<tr><td>([^<]+)</td>", worst_markers)
    assert rows[0] == "m010"
    worst_frames = page.split("<h2>Worst frames</h2>")[1].split("</table>")[0]
    codes = [int(x) for x in re.findall(r"<tr id='frame-(\d+)'>", worst_frames)][:3]
    assert sorted(codes) == [140, 141, 142]  # frames 40-42 at time code 100 + frame
    assert "residual (cm)" in worst_frames and "(cm)" in worst_markers
    assert "time codes 100 to 249" in page


def test_report_is_one_file_with_embedded_png_figures_and_no_links_out(spiked: Path) -> None:
    page = render_report(read_result_npz(spiked), source=str(spiked))
    srcs = re.findall(r"src='([^']+)'", page)
    assert len(srcs) >= 2
    for s in srcs:
        assert s.startswith("data:image/png;base64,")
        assert base64.b64decode(s.split(",", 1)[1])[:8] == b"\x89PNG\r\n\x1a\n"
    assert "http://" not in page and "https://" not in page


def test_cli_report_compares_two_solves_and_refuses_a_non_html_output(
    spiked: Path, tmp_path: Path
) -> None:
    solved = read_result_npz(spiked)
    shifted = tmp_path / "shifted.npz"
    write_result_npz(
        shifted,
        solved.topology,
        solved.vertices.astype(np.float64) + np.array([0.0, 0.0, 0.25]),
        solved.bundle_residuals,
        solved.missing,
        solved.marker_names,
        fps=solved.fps,
        start=solved.start,
        units=solved.units,
    )
    out = tmp_path / "r.html"
    p = lgi_cli("report", spiked, "-o", out, "--compare", shifted)
    assert p.returncode == 0, p.stderr
    page = out.read_text()
    assert "Difference to shifted.npz" in page
    assert re.search(r"Mean vertex distance over all frames 0\.25 cm", page)
    p = lgi_cli("report", spiked, "-o", tmp_path / "r.txt")
    assert p.returncode == 2 and "lgi: error: --out" in p.stderr and ".html" in p.stderr
    p = lgi_cli("report", spiked, "-o", tmp_path / "r2.html", "--take", spiked)
    assert p.returncode == 2 and "--take needs --model" in p.stderr


def test_lgi_solve_report_writes_the_page_of_the_solve_naming_a_swap(
    sample, tmp_path: Path
) -> None:  # type: ignore[no-untyped-def]
    from pipeline_files import write_actor, write_c3d

    actor = write_actor(tmp_path, sample, num_shapes=8)
    model = tmp_path / "m.lgi"
    p = lgi_cli("build", actor.neutral, actor.shapes, actor.markers, "-o", model, "--units", "cm")
    assert p.returncode == 0, p.stderr
    frames = np.asarray(sample.performance).copy()
    frames[40:90, [3, 50]] = frames[40:90, [50, 3]]
    write_c3d(tmp_path / "take.c3d", frames, actor.names, 30.0, "cm")
    page = tmp_path / "solve.html"
    p = lgi_cli(
        "solve",
        model,
        tmp_path / "take.c3d",
        "-o",
        tmp_path / "o.npz",
        "--report",
        page,
        "--no-repair",
    )
    assert p.returncode == 0, p.stderr
    pair = " &lt;-&gt; ".join(sorted((actor.names[3], actor.names[50])))
    assert f"likely label swap: {pair}, time codes 41-90" in page.read_text()
    assert f"likely label swap: {pair.replace('&lt;-&gt;', '<->')}" in p.stderr  # the summary
    p = lgi_cli(
        "solve",
        model,
        tmp_path / "take.c3d",
        "-o",
        tmp_path / "o2.npz",
        "--report",
        tmp_path / "r2.html",
        "--chunk",
        "10",
    )
    assert p.returncode == 2 and "--report needs the whole take solved at once" in p.stderr
    assert not (tmp_path / "o2.npz").exists()


def test_a_report_and_a_view_read_a_usd_cache_lgi_solve_wrote(spiked: Path, tmp_path: Path) -> None:
    from lgi.review.view import load

    usd = tmp_path / "spiked.usd"
    assert lgi_cli("export", spiked, "-o", usd, "-q").returncode == 0
    out = tmp_path / "r.html"
    p = lgi_cli("report", usd, "-o", out)
    assert p.returncode == 0, p.stderr
    page = out.read_text()
    worst = page.split("<h2>Worst markers</h2>")[1].split("</table>")[0]
    assert re.findall(r"<tr><td>([^<]+)</td>", worst)[0] == "m010"  # names kept in the USD
    assert "time codes 100 to 249" in page
    view = load(usd)
    npz = read_result_npz(spiked)
    np.testing.assert_array_equal(view.solved.vertices, npz.vertices)
    np.testing.assert_allclose(view.solved.bundle_residuals, npz.bundle_residuals, rtol=1e-6)


def test_the_viewer_answers_its_own_address_and_refuses_a_foreign_host(spiked: Path) -> None:
    """DNS rebinding: a request that reaches the port under another name gets 403, nothing of
    the take; the address `serve` printed (and `localhost` at its port) gets the page."""
    import http.client

    from lgi.review.view import load, serve

    server, url = serve(load(spiked))
    try:
        port = server.server_address[1]

        def get(host: str, path: str = "/meta.json") -> tuple[int, bytes]:
            conn = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
            try:
                conn.request("GET", path, headers={"Host": host})
                r = conn.getresponse()
                return r.status, r.read()
            finally:
                conn.close()

        assert url == f"http://127.0.0.1:{port}/"
        status, body = get(f"127.0.0.1:{port}")
        assert status == 200 and b'"frames"' in body
        assert get(f"localhost:{port}")[0] == 200
        for foreign in (f"evil.example:{port}", "127.0.0.1", f"127.0.0.1:{port + 1}", ""):
            status, body = get(foreign)
            assert status == 403 and b'"frames"' not in body, foreign
    finally:
        server.shutdown()
        server.server_close()
