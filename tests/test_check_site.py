"""The site check (docs/check_site.py) against small sites made here: the test of the test.

.ci/run runs ``docs/check_site.py`` on the real site after building it; these tests show that the
check finds what it is for and passes what is fine:

* a page showing ``{w=49%}`` under its pictures (the front page's old defect, with the HTML MyST
  wrote for it, and once more from a MyST page built here) fails, as do a broken image, a raw code
  fence, a directive name, a role left unresolved, pictures of a figure row stacked one under the
  other, and a JavaScript error;
* the same markup inside code, literals and math does not (the pages show MyST and reST syntax);
* "issue N" and a "Size:" note fail, on a guide page and on an API page (the docstrings) alike.

The pattern tests run without a browser; the others open the pages in headless Chromium (skipped
without it, unless DRAKE_HYBRID_REQUIRE_BROWSER=1, as .ci/run sets it).
"""

import os
import sys
import zlib
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[1] / "docs"
sys.path.insert(0, str(DOCS))

import check_site  # noqa: E402  (docs/, on the path above)


def _kinds(findings, page=None):
    return {finding.kind for finding in findings if page is None or finding.page == page}


# ------------------------------------------------------------------------------------------------
# The patterns, on text (no browser)
# ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("text, kind", [
    ("the eigenvalues its gains design.\n{w=49%} {w=49%}", "attribute braces"),
    ("a picture {width=\"49%\" .wide}", "attribute braces"),
    ("heading {#my-anchor}", "attribute braces"),
    ("```{note}\nA note\n```", "code fence"),
    ("before\n:::{figure} x.png\nafter", "code fence"),
    ("{note} This is a note", "directive name"),
    (".. warning:: careful", "directive name"),
    ("See :py:func:`drake_hybrid.simulate` for more", "unresolved role"),
    ("See :func:`simulate`", "unresolved role"),
    ("See {ref}`the-idea` for more", "unresolved role"),
    ("The controller on a real arm (issue 19)", "issue number"),
    ("Targets (issues 7, 14 and 31)", "issue number"),
    ("Issue 33 asks for a path error", "issue number"),
    ("Size: over half of the module is the system's docstring.", "maintainers' note"),
])
def test_each_pattern_finds_its_markup(text, kind):
    assert kind in _kinds(check_site.text_findings("guide.html", text))


@pytest.mark.parametrize("text", [
    "y_k = y_{k-1} + alpha (u_k - y_{k-1})",         # plain-text subscripts of the docstrings
    "10^{-3} and the set {a, b}",
    "C(r) = 0 on the end effector's configuration: the speed and force you ask for.",
    "a 2:1 ratio at 12:30, and a time of 1:02:03",
    "the issue is the pad's compression, 1.05 mm",
    "Sizes: 3 arms. The size of the pad: 20 mm.",
])
def test_ordinary_text_is_not_markup(text):
    assert check_site.text_findings("guide.html", text) == []


def test_a_note_made_a_definition_list_is_found_by_its_term():
    """docs/_ext/plain_docstrings.py reads 'Size: ...' followed by another 'word: ...' line as a field list."""
    findings = check_site.text_findings("guide.html", "Size\none idea\nincluded\nthe rest", terms=["Size", "included"])
    assert [finding.kind for finding in findings] == ["maintainers' note"]
    assert check_site.text_findings("guide.html", "size\nthe pad's", terms=["size", "Sizes", "mode"]) == []


def test_bookkeeping_fails_on_every_page_the_api_reference_included():
    text = "Baselines (issue 18).\nSize: one module for every figure."
    for page in ("reference/generated/drake_hybrid.viz.run_plots.html", "howto/path.html"):
        assert _kinds(check_site.text_findings(page, text)) == {"issue number", "maintainers' note"}


# ------------------------------------------------------------------------------------------------
# Sites in headless Chromium
# ------------------------------------------------------------------------------------------------

def _png(width=8, height=6):
    """A small valid PNG (grey)."""
    def chunk(kind, data):
        body = kind + data
        return len(data).to_bytes(4, "big") + body + zlib.crc32(body).to_bytes(4, "big")
    raw = b"".join(b"\x00" + b"\x80" * (3 * width) for _ in range(height))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", width.to_bytes(4, "big") + height.to_bytes(4, "big")
                                         + bytes([8, 2, 0, 0, 0]))
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


ROW_CSS = (".figure-row { display: grid; grid-template-columns: repeat(2, minmax(0, 1fr)); gap: 1rem; }"
           " .figure-row > figure { margin: 0; } .figure-row img { width: 100%; height: auto; }")


def _page(body, css=""):
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>A page</title><style>{css}</style></head>"
            f"<body><article role='main'>{body}</article></body></html>")


def _figure(src, caption):
    return f"<figure><img src='{src}' alt='{caption}'><figcaption><p>{caption}</p></figcaption></figure>"


# page -> (its body, its CSS): one defect a page, the clean pages first.
PAGES = {
    "index.html": (f"<h1>drake_hybrid</h1><p>Hybrid control.</p>"
                   f"<div class='figure-row docutils container'>{_figure('_images/a.png', 'A 3R arm')}"
                   f"{_figure('_images/b.png', 'A Panda')}</div>", ROW_CSS),
    # markup shown as code, literals and math is what the page means: nothing to find
    "syntax.html": ("<p>Write <code class='docutils literal'><span class='pre'>{w=49%}</span></code> or "
                    "<code>:py:func:`x`</code>; a note is <code>{note}</code>.</p>"
                    "<div class='highlight'><pre>```{note}\nA note\n```\n.. warning:: careful\n:::{figure} x.png\n:::"
                    "</pre></div><p><span class='math notranslate nohighlight'>\\(x_{i} = \\{a=1\\}\\)</span></p>"
                    "<p>Tutorial 7's arm, at y_{k-1}.</p>", ""),
    # the front page's old defect, as MyST wrote it for ![alt](src){w=49%} (the % is not a bare value)
    "braces.html": ("<p><img alt='3R arm washing a window (Meshcat)' src='_images/a.png' />{w=49%} "
                    "<img alt='Franka Panda polishing a drum (Meshcat)' src='_images/b.png' />{w=49%}</p>", ""),
    "broken_image.html": ("<p>A picture: <img src='_images/missing.png' alt='gone'></p>", ""),
    "zero_size_image.html": ("<p>A picture: <img src='_images/a.png' alt='flat' style='height: 0'></p>", ""),
    "fence.html": ("<p>```{note}\nA note the parser did not take\n```</p>", ""),
    "directive.html": ("<p>{note} A note the parser did not take</p>", ""),
    "role.html": ("<p>Call :py:func:`drake_hybrid.simulate` first.</p>", ""),
    "myst_role.html": ("<p>See {ref}`the-idea`.</p>", ""),
    "stacked_row.html": (f"<div class='figure-row'>{_figure('_images/a.png', 'A')}{_figure('_images/b.png', 'B')}"
                         f"</div>", ""),
    "uncaptioned_row.html": ("<div class='figure-row'><figure><img src='_images/a.png'></figure>"
                             "<figure><img src='_images/b.png'></figure></div>", ROW_CSS),
    "script_error.html": ("<p>Fine text.</p><script>undefined_function_of_the_page();</script>", ""),
    "issue.html": ("<h1>The controller on a real arm (issue 19)</h1>", ""),
    "field_note.html": ("<dl class='simple'><dt>Size</dt><dd><p>one idea, the run's configuration (units</p></dd>"
                        "<dt>included</dt><dd><p>and its validation.</p></dd></dl>", ""),
    "reference/generated/drake_hybrid.notes.html": ("<h1>notes</h1><p>Baselines (issue 18).</p>"
                                                    "<p>Size: over half of the module is its docstring.</p>", ""),
}
CLEAN = {"index.html", "syntax.html"}
EXPECTED = {
    "braces.html": {"attribute braces"},
    "broken_image.html": {"broken image", "page error"},          # the image, and the file the page asked for
    "zero_size_image.html": {"broken image"},
    "fence.html": {"code fence", "directive name"},        # ```{note}: a fence and a directive's name
    "directive.html": {"directive name"},
    "role.html": {"unresolved role"},
    "myst_role.html": {"unresolved role"},
    "stacked_row.html": {"figure row"},
    "uncaptioned_row.html": {"figure row"},
    "script_error.html": {"page error"},
    "issue.html": {"issue number"},
    "field_note.html": {"maintainers' note"},
    "reference/generated/drake_hybrid.notes.html": {"issue number", "maintainers' note"},
}


def _chromium_or_skip():
    try:
        return check_site.chromium_executable()
    except FileNotFoundError as error:
        if os.environ.get("DRAKE_HYBRID_REQUIRE_BROWSER") == "1":
            pytest.fail(str(error))
        pytest.skip(str(error))


def _write_site(root, pages):
    (root / "_images").mkdir(parents=True)
    (root / "_images" / "a.png").write_bytes(_png(90, 52))
    (root / "_images" / "b.png").write_bytes(_png(90, 52))
    for name, (body, css) in pages.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        prefix = "../" * name.count("/")
        path.write_text(_page(body.replace("'_images/", f"'{prefix}_images/"), css))
    return root


@pytest.fixture(scope="module")
def checked(tmp_path_factory):
    executable = _chromium_or_skip()
    site = _write_site(tmp_path_factory.mktemp("site") / "html", PAGES)
    screenshots = site.parent / "screenshots"
    return site, check_site.check_site(site, screenshots=screenshots, executable=executable), executable


@pytest.mark.browser
def test_every_page_is_loaded_and_the_clean_pages_pass(checked):
    site, report, _ = checked
    assert report.pages == len(PAGES) and not report.skipped
    for page in CLEAN:
        assert not [finding for finding in report.findings if finding.page == page], page
    assert not report.ok


@pytest.mark.browser
@pytest.mark.parametrize("page", sorted(EXPECTED))
def test_each_defect_fails_the_check(checked, page):
    """The test of the test: each page's one defect is found, fails, and nothing else is reported."""
    _, report, _ = checked
    assert _kinds(report.failures, page) == EXPECTED[page], [str(f) for f in report.findings if f.page == page]


@pytest.mark.browser
def test_the_front_page_defect_is_reported_where_a_reader_sees_it(checked):
    _, report, _ = checked
    details = [finding.detail for finding in report.failures if finding.page == "braces.html"]
    assert len(details) == 2 and all("'{w=49%}'" in detail for detail in details), details
    stacked = [finding.detail for finding in report.failures if finding.page == "stacked_row.html"]
    assert any("not side by side at 1400 px" in detail for detail in stacked), stacked


@pytest.mark.browser
def test_screenshots_of_the_front_page_and_an_api_page(checked):
    site, report, _ = checked
    names = sorted(path.name for path in report.screenshots)
    assert names == ["api_page_narrow.png", "api_page_wide.png", "front_page_narrow.png", "front_page_wide.png"]
    for path in report.screenshots:
        assert path.parent == site.parent / "screenshots" and path.read_bytes().startswith(b"\x89PNG")


@pytest.mark.browser
def test_a_myst_page_with_the_old_attribute_syntax_fails_and_the_figure_row_passes(tmp_path):
    """End to end: MyST (attrs_inline, as docs/conf.py enables it) prints ``{w=49%}`` as text, because
    a bare attribute value may not hold '%'; the figure row of docs/index.md renders side by side."""
    executable = _chromium_or_skip()
    from sphinx.cmd.build import build_main

    source = tmp_path / "source"
    (source / "_static").mkdir(parents=True)
    (source / "a.png").write_bytes(_png(90, 52))
    (source / "_static" / "site.css").write_text((DOCS / "_static" / "site.css").read_text())
    (source / "conf.py").write_text('extensions = ["myst_parser"]\nmyst_enable_extensions = ["colon_fence", '
                                    '"attrs_inline"]\nhtml_static_path = ["_static"]\nhtml_css_files = ["site.css"]\n')
    (source / "index.md").write_text(
        "# Front\n\n![one](a.png){w=49%} ![two](a.png){w=49%}\n\n```{toctree}\nrow\n```\n")
    (source / "row.md").write_text(
        "# Row\n\n::::{container} figure-row\n:::{figure} a.png\n:alt: one\n\nThe first\n:::\n"
        ":::{figure} a.png\n:alt: two\n\nThe second\n:::\n::::\n")
    site = tmp_path / "html"
    assert build_main(["-q", "-b", "html", str(source), str(site)]) == 0
    report = check_site.check_site(site, executable=executable, pages=["index.html", "row.html"])
    assert _kinds(report.failures, "index.html") == {"attribute braces"}
    assert not [str(f) for f in report.findings if f.page == "row.html"]


@pytest.mark.browser
def test_the_command_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("DRAKE_HYBRID_CHROMIUM", _chromium_or_skip())
    good = _write_site(tmp_path / "good", {name: PAGES[name] for name in CLEAN})
    bad = _write_site(tmp_path / "bad", {name: PAGES[name] for name in ("index.html", "braces.html")})
    assert check_site.main([str(good), "--screenshots", str(tmp_path / "shots")]) == 0
    assert (tmp_path / "shots" / "front_page_wide.png").is_file()
    assert check_site.main([str(bad), "--screenshots", str(tmp_path / "shots")]) == 1
    out = capsys.readouterr().out
    assert "braces.html: attribute braces: '{w=49%}'" in out and "0 failures" in out and "2 failures" in out


def test_without_a_browser_the_check_skips_unless_one_is_required(tmp_path, monkeypatch, capsys):
    site = _write_site(tmp_path / "html", {"index.html": PAGES["index.html"]})

    def missing():
        raise FileNotFoundError("no Chromium found")

    monkeypatch.setattr(check_site, "chromium_executable", missing)
    monkeypatch.setenv("DRAKE_HYBRID_REQUIRE_BROWSER", "0")
    assert check_site.main([str(site)]) == 0 and "skipped" in capsys.readouterr().out
    monkeypatch.setenv("DRAKE_HYBRID_REQUIRE_BROWSER", "1")
    assert check_site.main([str(site)]) == 2
    assert check_site.main([str(tmp_path / "nothing")]) == 2
