"""Meshcat animations: the task's camera, and a check that a saved animation renders.

``simulate(config, meshcat=Meshcat(), record_html=True).html`` (or
``drake-hybrid simulate TASK --html FILE``) is Meshcat's ``StaticHtml()``: one
self-contained file with the scene, the recorded animation and the viewer's
JavaScript inlined, which plays offline in any browser (2.3 MB plus about
30 kB per simulated second for the window task).

* ``quiet_meshcat()``: a ``Meshcat`` without Drake's "Meshcat listening for connections at ..."
  INFO line (a recording needs no browser connected; the command line does not print it).
* ``set_task_camera(meshcat, task)``: the task's preferred view (its
  ``camera`` attribute: camera position and target in world, m).
* ``render_html(html, png)``: open an HTML file in headless Chromium (Debian's
  ``chromium``, driven by Playwright from PyPI), block every request that is
  not a local file, take screenshots and report what the page logged
  (``PageReport``). Used by the tests and by ``docs/make_figures.py``.
"""

import logging
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.image import imread

from pydrake.geometry import Meshcat

# Chromium in a container without a GPU or a network: software WebGL (SwiftShader; Chromium 156
# renders Meshcat with or without --enable-unsafe-swiftshader) and no background connections, which
# a closed network refuses.
CHROMIUM_FLAGS = ("--no-sandbox", "--disable-gpu", "--enable-unsafe-swiftshader", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync")


def quiet_meshcat(**kwargs):
    """``pydrake.geometry.Meshcat(**kwargs)`` with Drake's logger (Python's "drake" logger, which
    pydrake keeps in step with spdlog's level) at WARNING while it starts, so that its INFO line
    "Meshcat listening for connections at http://localhost:7000" is not printed; the logger's level
    is restored afterwards."""
    logger = logging.getLogger("drake")
    level = logger.level
    logger.setLevel(max(logging.WARNING, level))
    try:
        return Meshcat(**kwargs)
    finally:
        logger.setLevel(level)


def set_task_camera(meshcat, task):
    """Point Meshcat's camera as ``task.camera`` = (camera position, target) asks; no-op without one."""
    camera = getattr(task, "camera", None)
    if camera is not None:
        position, target = camera
        meshcat.SetCameraPose(np.asarray(position, dtype=float), np.asarray(target, dtype=float))


def chromium_executable():
    """Path of a Chromium binary; FileNotFoundError saying how to install one."""
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    raise FileNotFoundError("no Chromium found on PATH; install Debian's package: apt-get install chromium")


@dataclass
class PageReport:
    """What a page did in headless Chromium."""

    screenshots: list                                       # PNG paths, one per ``times`` entry
    console_errors: list = field(default_factory=list)      # console messages of type "error"
    page_errors: list = field(default_factory=list)         # uncaught JavaScript exceptions
    blocked_requests: list = field(default_factory=list)    # non-file URLs the page tried to load
    console_messages: list = field(default_factory=list)    # every (type, text)

    @property
    def clean(self):
        return not (self.console_errors or self.page_errors or self.blocked_requests)


def image_statistics(png_path):
    """(fraction of saturated pixels, number of distinct colours after quantizing to 4 bits per
    channel) of a PNG: a blank or failed WebGL canvas has neither."""
    image = imread(str(png_path))[..., :3]
    pixels = image.reshape(-1, 3)
    maximum, minimum = pixels.max(axis=1), pixels.min(axis=1)
    saturation = np.where(maximum > 0, (maximum - minimum) / np.maximum(maximum, 1e-9), 0.0)
    saturated = float(np.mean((saturation > 0.35) & (maximum > 0.2)))
    distinct = len(np.unique(np.round(pixels * 15).astype(int), axis=0))
    return saturated, distinct


# CSS that hides Meshcat's control panel (dat.gui), for figures.
HIDE_MESHCAT_CONTROLS = ".dg.main { display: none !important; }"


SEEK_RENDER_WAIT_MS = 500     # after a seek, time for the viewer's render loop to draw the new frame


def render_html(html_path, png_path=None, times=(1.5,), width=960, height=600, executable=None, style=None,
                seek=False, restart=False):
    """Open ``html_path`` in headless Chromium and screenshot it ``times`` seconds after load
    (or, with ``seek``, at those times of the recorded animation: it is paused and moved there;
    with ``restart``, ``times`` after the recording is started again from t = 0 once the page has
    loaded: Meshcat plays a recording once on load, and on a busy machine loading the 2-3 MB page can
    take longer than a short recording, which then shows its last frame at every screenshot).

    Only file:, data: and blob: URLs may load (the others are blocked and
    reported, proving the page works offline). ``style``: CSS added to the
    page (e.g. ``HIDE_MESHCAT_CONTROLS``). Returns a ``PageReport``;
    screenshots go to ``png_path`` (with ``_1``, ``_2`` ... for later times).
    """
    from playwright.sync_api import sync_playwright

    html_path = Path(html_path).resolve()
    if not html_path.is_file():
        raise FileNotFoundError(f"no HTML file at {html_path}")
    png_path = Path(png_path) if png_path is not None else html_path.with_suffix(".png")
    report = PageReport(screenshots=[])
    local = ("file:", "data:", "blob:")

    def route(route_handle):
        url = route_handle.request.url
        if url.startswith(local):
            route_handle.continue_()
        else:
            report.blocked_requests.append(url)
            route_handle.abort()

    def on_console(message):
        report.console_messages.append((message.type, message.text))
        if message.type == "error":
            report.console_errors.append(message.text)

    with tempfile.TemporaryDirectory(prefix="chromium-profile-") as profile, sync_playwright() as playwright:
        browser = playwright.chromium.launch_persistent_context(
            profile, executable_path=executable or chromium_executable(), headless=True, args=list(CHROMIUM_FLAGS),
            viewport={"width": int(width), "height": int(height)})
        try:
            page = browser.new_page()
            page.on("console", on_console)
            page.on("pageerror", lambda error: report.page_errors.append(str(error)))
            page.route("**/*", route)
            page.goto(html_path.as_uri())
            page.wait_for_selector("canvas", timeout=30000)
            if style:
                page.add_style_tag(content=style)
            if restart:
                page.evaluate("viewer.animator.pause(); viewer.animator.seek(0); viewer.animator.play();")
            elapsed = 0.0
            for i, moment in enumerate(times):
                if seek:
                    # Meshcat's Animator (the page's global ``viewer``): pause, then move every action to t.
                    page.evaluate(f"viewer.animator.pause(); viewer.animator.seek({float(moment)});")
                    page.wait_for_timeout(SEEK_RENDER_WAIT_MS)
                else:
                    page.wait_for_timeout(max(0.0, moment - elapsed) * 1000)
                    elapsed = moment
                path = png_path if i == 0 else png_path.with_name(f"{png_path.stem}_{i}{png_path.suffix}")
                page.screenshot(path=str(path))
                report.screenshots.append(path)
        finally:
            browser.close()
    return report
