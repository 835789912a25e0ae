"""`lgi view` in a real browser: Debian's Chromium driven headless by selenium through the
system chromedriver (never a downloaded browser). The page must load without console errors,
draw the face, change pixels when the frame moves or the colouring switches to A/B, and land on
the frame a report link or a heatmap click names. Skips, saying why, where no browser is
installed (the README's test command installs one)."""

from __future__ import annotations

import io
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
import pytest

import headless
from pipeline_files import spiked_sample_take, write_solve

BACKGROUND = np.array([0xF4, 0xF4, 0xF4])


def _browser() -> Any:
    why = headless.missing()
    if why is not None:
        pytest.skip(why)
    return headless.chromium()


@pytest.fixture(scope="module")
def solved_pair(sample, sample_model, tmp_path_factory):  # type: ignore[no-untyped-def]
    """The spiked sample take solved noise-aware (A) and exactly (B), with its markers, from
    time code 100."""
    frames = spiked_sample_take(sample, sample_model)
    folder = tmp_path_factory.mktemp("view")
    return [
        write_solve(folder / "noise-aware.npz", sample_model, frames, 0.02),
        write_solve(folder / "exact.npz", sample_model, frames, None),
    ]


@pytest.fixture(scope="module")
def page(solved_pair) -> Iterator[tuple[Any, str]]:  # type: ignore[no-untyped-def]
    from lgi.review import view

    driver = _browser()
    server, url = view.serve(view.load(solved_pair[0], solved_pair[1]))
    try:
        yield driver, url
    finally:
        driver.quit()
        server.shutdown()
        server.server_close()


def _wait(driver: Any, script: str, want: str, timeout: float = 30.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if driver.execute_script(script) == want:
            return
        time.sleep(0.05)
    raise AssertionError(f"{script} never became {want!r}: {driver.execute_script(script)!r}")


def _open(driver: Any, url: str) -> None:
    driver.get(url)
    _wait(driver, "return document.body.dataset.ready", "1")


def _stage_pixels(driver: Any) -> np.ndarray:
    """The 3D view's pixels (RGB) from a screenshot of the stage element."""
    from matplotlib.image import imread

    png = driver.find_element("id", "stage").screenshot_as_png
    return (imread(io.BytesIO(png))[..., :3] * 255).round().astype(np.int16)


def _errors(driver: Any) -> list[str]:
    return [e["message"] for e in driver.get_log("browser") if e["level"] == "SEVERE"]


def _frame(driver: Any, code: int) -> None:
    driver.execute_script(
        "const s = document.getElementById('slider'); s.value = arguments[0];"
        "s.dispatchEvent(new Event('input'));",
        code - 100,
    )
    _wait(driver, "return document.body.dataset.frame", str(code))


def test_page_loads_without_console_errors_and_draws_the_face(page) -> None:  # type: ignore[no-untyped-def]
    driver, url = page
    _open(driver, url)
    assert driver.execute_script("return document.body.dataset.frame") == "100"
    pixels = _stage_pixels(driver)
    face = np.abs(pixels - BACKGROUND).sum(axis=2) > 30
    # The sample's face fills a good part of the view, and is shaded, not a flat blot.
    assert 0.10 < face.mean() < 0.90, face.mean()
    assert pixels[face].std() > 10
    assert _errors(driver) == []


def test_moving_the_frame_slider_changes_the_pixels(page) -> None:  # type: ignore[no-untyped-def]
    driver, url = page
    _open(driver, url)
    _frame(driver, 100)
    before = _stage_pixels(driver)
    _frame(driver, 175)  # mid-performance: the jaw is open (lgi.lab.sample)
    after = _stage_pixels(driver)
    changed = np.abs(after - before).sum(axis=2) > 30
    assert changed.mean() > 0.005, changed.mean()
    _frame(driver, 100)
    again = _stage_pixels(driver)
    assert np.abs(again - before).sum(axis=2).max() <= 30  # the same frame draws the same
    assert _errors(driver) == []


def test_a_b_colouring_differs_from_the_plain_one(page) -> None:  # type: ignore[no-untyped-def]
    from selenium.webdriver.support.ui import Select

    driver, url = page
    _open(driver, url)
    _frame(driver, 141)
    plain = _stage_pixels(driver)
    Select(driver.find_element("id", "colour")).select_by_value("difference")
    _wait(driver, "return document.body.dataset.colour", "difference")
    _frame(driver, 141)
    time.sleep(0.3)
    ab = _stage_pixels(driver)
    differs = np.abs(ab - plain).sum(axis=2) > 60
    assert differs.mean() > 0.05, differs.mean()
    # Viridis over grey: the A/B view has coloured pixels the plain one lacks. Viridis' low end
    # (purple, chroma 83 in full light) is shaded on the face, so chroma > 40 counts a hue.
    sat = lambda p: (p.max(axis=2) - p.min(axis=2)) > 40  # noqa: E731
    assert sat(ab).mean() > sat(plain).mean() + 0.05
    assert _errors(driver) == []


def test_a_worst_frame_link_in_the_report_opens_the_viewer_at_that_frame(page) -> None:  # type: ignore[no-untyped-def]
    driver, url = page
    driver.get(url + "report.html")
    link = driver.find_element("css selector", "tr[id^='frame-'] a")
    code = link.text
    assert code in ("140", "141", "142")  # the spike's frames are the worst
    link.click()
    _wait(driver, "return document.body.dataset.ready", "1")
    _wait(driver, "return document.body.dataset.frame", code)
    assert driver.find_element("id", "slider").get_attribute("value") == str(int(code) - 100)
    assert _errors(driver) == []


def test_clicking_the_heatmap_seeks_the_frame_under_the_pointer(page) -> None:  # type: ignore[no-untyped-def]
    from selenium.webdriver.common.action_chains import ActionChains

    driver, url = page
    _open(driver, url)
    heat = driver.find_element("id", "heatmap")
    width = heat.size["width"]
    # Pointer at 30.5 % of the width: frame floor(0.305 * 150) = 45, time code 145.
    x = round(0.305 * width) - width // 2
    ActionChains(driver).move_to_element_with_offset(heat, x, 0).click().perform()
    got = int(driver.execute_script("return document.body.dataset.frame"))
    _wait(driver, "return document.body.dataset.frame", str(got))
    assert abs(got - 145) <= 1, got
    assert _errors(driver) == []


def test_clicking_a_heatmap_cell_in_the_report_opens_the_viewer_at_that_frame(page) -> None:  # type: ignore[no-untyped-def]
    driver, url = page
    driver.get(url + "report.html")
    # A real click (trusted event) at the middle of frame 60's column (time code 160), a
    # quarter down the markers, after scrolling the picture's top into view.
    driver.execute_script(
        "const img = document.getElementById('heatmap'); img.scrollIntoView({block: 'start'});"
    )
    box = driver.execute_script(
        "const img = document.getElementById('heatmap'); const r = img.getBoundingClientRect();"
        "const [l, t, w, h] = img.dataset.box.split(',').map(Number);"
        "return [r.left + r.width * (l + w * 60.5 / 150), r.top + r.height * (t + h * 0.25)];"
    )
    from selenium.webdriver.common.actions.action_builder import ActionBuilder

    actions = ActionBuilder(driver)
    actions.pointer_action.move_to_location(int(box[0]), int(box[1])).click()
    actions.perform()
    _wait(driver, "return document.body.dataset.ready", "1")
    # The viewer seeks to the link's #frame once its first chunk is in: poll, so a slow
    # machine is not read between "ready" and the seek.
    end = time.monotonic() + 30.0
    got = -1
    while time.monotonic() < end:
        got = int(driver.execute_script("return document.body.dataset.frame"))
        if abs(got - 160) <= 1:
            break
        time.sleep(0.05)
    assert abs(got - 160) <= 1, got
    assert _errors(driver) == []


def test_a_solve_that_repaired_markers_lists_them_and_seeks_to_them(
    sample, sample_model, tmp_path
) -> None:  # type: ignore[no-untyped-def]
    """The settings' repairs are listed under the heatmap; a click opens the frame."""
    from dataclasses import replace

    from lgi.io.result import read_result_npz, write_result_npz
    from lgi.io.settings import SolveSettings
    from lgi.review import view

    plain = read_result_npz(write_solve(tmp_path / "a.npz", sample_model, sample.performance, 0.02))
    settings = replace(
        SolveSettings.of(has_jaw_rig=False, jaw=None, marker_noise=0.02, detail_weight=None),
        repairs=(("spike", ("m010",), 40, 42),),
    )
    path = write_result_npz(
        tmp_path / "repaired.npz",
        plain.topology,
        plain.vertices,
        plain.bundle_residuals,
        plain.missing,
        plain.marker_names,
        fps=plain.fps,
        start=plain.start,
        units=plain.units,
        markers=plain.markers,
        settings=settings,
    )
    driver = _browser()
    server, url = view.serve(view.load(path))
    try:
        _open(driver, url)
        items = driver.execute_script(
            "return [...document.querySelectorAll('#repaired button')].map(b => b.textContent)"
        )
        assert items == ["m010 solved as missing (a spike), time codes 140-142"]
        driver.execute_script("document.querySelector('#repaired button').click()")
        _wait(driver, "return document.body.dataset.frame", "140")
        assert _errors(driver) == []
    finally:
        driver.quit()
        server.shutdown()
        server.server_close()
