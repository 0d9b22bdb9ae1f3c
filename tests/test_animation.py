"""The 3-D animation: `drake-hybrid simulate --html` writes a self-contained page that renders in a browser.

The browser test opens the page in headless Chromium (Debian's ``chromium``;
``.ci/run`` installs it when it is missing) with every non-file request
blocked, and checks from screenshots that the scene renders and moves, with no
console errors. Without Chromium it is skipped, unless
DRAKE_HYBRID_REQUIRE_BROWSER=1 (set by ``.ci/run``) makes that a failure.
"""

import os
import re

import numpy as np
import pytest

from drake_hybrid.cli import main
from drake_hybrid.tasks.registry import get_task
from drake_hybrid.viz.animation import chromium_executable, image_statistics, render_html, set_task_camera


def _chromium_or_skip():
    try:
        return chromium_executable()
    except FileNotFoundError as error:
        if os.environ.get("DRAKE_HYBRID_REQUIRE_BROWSER") == "1":
            pytest.fail(str(error))
        pytest.skip(str(error))


@pytest.fixture(scope="module")
def animation(tmp_path_factory):
    out = tmp_path_factory.mktemp("animation")
    html = out / "window_washing.html"
    assert main(["simulate", "window-washing", "--duration", "2.0", "--out", str(out / "run"), "--html", str(html),
                 "--no-progress", "--no-plots"]) == 0
    return html


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_html_is_self_contained(animation):
    text = animation.read_text()
    assert text.lstrip().lower().startswith("<!doctype html>")
    # Meshcat's viewer and the recording are inlined: no script or stylesheet is fetched from elsewhere.
    assert re.search(r"<script[^>]*\bsrc\s*=", text, re.IGNORECASE) is None
    assert re.search(r"<link[^>]*\bhref\s*=", text, re.IGNORECASE) is None
    assert "animation" in text and 2e6 < len(text) < 4e6      # viewer (about 2.3 MB) plus 2 s of recording


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
@pytest.mark.browser
def test_animation_renders_offline_in_headless_chromium(animation, tmp_path):
    executable = _chromium_or_skip()
    # restart: the recording played from t = 0 once the page is up (under load the page can take longer
    # to load than the 2 s recording lasts, and both screenshots would show its last frame).
    report = render_html(animation, tmp_path / "frame.png", times=(0.4, 1.6), executable=executable, restart=True)
    assert report.blocked_requests == [], "the page tried to load something that is not in the file"
    assert report.console_errors == [] and report.page_errors == [], (report.console_errors, report.page_errors)
    # Not blank: an empty Meshcat scene (background and grid) measures 0.04 % saturated pixels and 44
    # colours; this scene (orange, blue and green links, yellow pad) about 0.6 % and 250.
    saturated, colours = image_statistics(report.screenshots[0])
    assert saturated > 0.002 and colours > 100, (saturated, colours)
    # It moves: the arm wipes along the window between the two screenshots.
    from matplotlib.image import imread

    first, later = (imread(str(path))[..., :3] for path in report.screenshots)
    changed = np.mean(np.abs(first - later).max(axis=2) > 0.05)
    assert changed > 1e-3, f"only {changed:.2%} of the pixels changed: the animation does not play"


@pytest.mark.slow                # several seconds: not in the fast loop (-m 'not slow')
def test_seek_shows_the_recording_at_the_asked_time(animation, tmp_path):
    """With ``seek`` the screenshots are frames of the recording at those simulation times: the
    same time twice gives the same picture, the start and the end of the 2 s wipe differ."""
    executable = _chromium_or_skip()
    report = render_html(animation, tmp_path / "seek.png", times=(0.0, 2.0, 0.0), executable=executable, seek=True)
    assert report.console_errors == [] and report.page_errors == [], (report.console_errors, report.page_errors)
    from matplotlib.image import imread

    start, end, start_again = (imread(str(path))[..., :3] for path in report.screenshots)

    def changed(a, b):
        return np.mean(np.abs(a - b).max(axis=2) > 0.05)

    assert changed(start, end) > 1e-3, "seeking to the end shows the same picture as the start"
    assert changed(start, start_again) < 1e-4, "seeking back to t = 0 does not show the start again"


def test_task_camera():
    class FakeMeshcat:
        calls = []

        def SetCameraPose(self, position, target):
            self.calls.append((position, target))

    meshcat = FakeMeshcat()
    set_task_camera(meshcat, get_task("window-washing"))
    position, target = meshcat.calls[-1]
    assert position.shape == (3,) and target.shape == (3,)
    set_task_camera(meshcat, object())            # a task without a camera: nothing happens
    assert len(meshcat.calls) == 1


def test_render_html_names_a_missing_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="no HTML file"):
        render_html(tmp_path / "missing.html")
