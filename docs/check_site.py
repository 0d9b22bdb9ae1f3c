"""Check the built site as a reader sees it: every page opened in headless Chromium.

    python docs/check_site.py docs/_build/html            # after the Sphinx build (.ci/run does)

A clean ``sphinx -W`` build and resolving links (``check_links.py``) do not make a clean page: a
syntax the parser did not take is printed as text, and nothing warns. Every page of the site is
loaded from the files (only file:, data: and blob: URLs load, the rest is blocked: no network) and

* its rendered text (outside code, literals and math) must show no raw markup: attribute braces
  such as ``{w=49%}``, code fences (three backticks, tildes or colons), directive names such as
  ``{note}`` or ``.. note::``, roles left unresolved such as ``:py:func:`x``` or ``{ref}`x```;
* every image must load (a picture of non-zero natural size, and non-zero size on the page unless
  it is hidden), and no file the page asks for may be missing;
* it must raise no JavaScript error;
* the pictures of a ``figure-row`` container (the front page's two, docs/_static/site.css) must sit
  side by side, each with its caption, at a phone's width and at a desktop's;
* the reader's text must not cite the project's bookkeeping: "issue N" (a tracker a reader cannot
  follow) or a maintainers' "Size: ..." note meant for the code.


Screenshots of the front page (a wide and a narrow window) and of one API page are written to
``docs/_build/screenshots/`` (``--screenshots``) for a person to look at.

Exit status: 0 clean, 1 a failure (each printed with its page), 2 no site. Without Chromium the
check is skipped (exit 0), unless DRAKE_HYBRID_REQUIRE_BROWSER=1 (set by .ci/run): then exit 2.
"""

import argparse
import os
import re
import shutil
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

# Debian's chromium in a container: no sandbox, no GPU, no background connections (the network is closed).
CHROMIUM_FLAGS = ("--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync")
LOCAL_URLS = ("file:", "data:", "blob:", "about:")

# Raw markup in the rendered text (code, literals and math are not searched): (kind, pattern).
_ATTRIBUTE = r"""(?:[#.][A-Za-z][\w-]*|[A-Za-z][\w-]*=(?:"[^"]*"|'[^']*'|[^\s}]+))"""
RAW_MARKUP = (
    ("attribute braces", re.compile(r"\{\s*" + _ATTRIBUTE + r"(?:\s+" + _ATTRIBUTE + r")*\s*\}")),
    ("code fence", re.compile(r"`{3,}|^[ \t]*(?:~{3,}|:{3,})", re.M)),
    # not a subscript or superscript written in plain text, y_{k-1} or 10^{-3}
    ("directive name", re.compile(r"(?<![\w^])\{[a-z][\w-]*(?::[\w-]+)*\}(?!`)|^[ \t]*\.\. [a-z][\w:-]*::", re.M)),
    ("unresolved role", re.compile(r"(?<![\w`]):(?:[a-z]+:)*[a-z]+:`[^`\n]+`|\{[a-z][\w-]*(?::[\w-]+)*\}`[^`\n]+`")),
)
# The project's bookkeeping in the reader's text.
BOOKKEEPING = (
    ("issue number", re.compile(r"\b[Ii]ssues?\s+#?\d+(?:(?:,\s*|\s+and\s+)#?\d+)*")),
    ("maintainers' note", re.compile(r"^[ \t]*Size:.*", re.M)),
)
# A maintainers' note the docstrings' field lines made a definition list of (docs/_ext/plain_docstrings.py).
NOTE_TERMS = re.compile(r"Size:?")
# The API page screenshotted: the first of these the site has, else its first API page.
API_PAGES = ("reference/generated/drake_hybrid.control.controller.html",)
WIDE, NARROW = {"width": 1400, "height": 900}, {"width": 390, "height": 844}

# In the page: its text outside code, literals and math (a new line at each block's start), its
# images once loaded, its figure rows. Run after the images were made eager and waited for.
_PROBE = r"""
() => {
  const SKIP = 'pre, code, kbd, samp, tt, script, style, noscript, template, .math, mjx-container, .MathJax, .highlight';
  const BLOCK = new Set(['P', 'LI', 'DT', 'DD', 'H1', 'H2', 'H3', 'H4', 'H5', 'H6', 'TD', 'TH', 'DIV', 'SECTION',
    'ARTICLE', 'FIGCAPTION', 'CAPTION', 'BLOCKQUOTE', 'TR', 'NAV', 'ASIDE', 'HEADER', 'FOOTER', 'MAIN', 'BODY',
    'FIGURE', 'UL', 'OL', 'DL', 'TABLE', 'LABEL', 'BUTTON', 'SUMMARY', 'DETAILS', 'FORM']);
  const block = (node) => { let e = node.parentElement; while (e && !BLOCK.has(e.tagName)) e = e.parentElement; return e; };
  const parts = [];
  let last = null;
  const walker = document.createTreeWalker(document.body, NodeFilter.SHOW_TEXT);
  for (let node = walker.nextNode(); node; node = walker.nextNode()) {
    if (!node.nodeValue.trim() || node.parentElement.closest(SKIP)) continue;
    const here = block(node);
    if (here !== last) { parts.push('\n'); last = here; }
    parts.push(node.nodeValue);
  }
  const shown = (e) => e.getClientRects().length > 0 && getComputedStyle(e).visibility !== 'hidden';
  const images = [...document.images].map((img) => {
    const box = img.getBoundingClientRect();
    return {src: img.getAttribute('src') || '', complete: img.complete, natural: [img.naturalWidth, img.naturalHeight],
            size: [box.width, box.height], shown: shown(img)};
  });
  const rows = [...document.querySelectorAll('.figure-row')].map((row) => [...row.children].map((figure) => {
    const img = figure.querySelector('img'), caption = figure.querySelector('figcaption');
    const box = (e) => { if (!e) return null; const r = e.getBoundingClientRect(); return [r.left, r.top, r.width, r.height]; };
    return {image: box(img), caption: caption && shown(caption) ? caption.innerText.trim() : '', captionBox: box(caption)};
  }));
  const terms = [...document.querySelectorAll('dt, th.field-name')].map((e) => e.innerText.trim());
  return {title: document.title, text: parts.join('').replace(/[ \t\u00a0]+/g, ' '), images, rows, terms};
}
"""
_LOAD_IMAGES = r"""
async () => {
  const images = [...document.images];
  images.forEach((img) => { img.loading = 'eager'; });
  await Promise.all(images.map((img) => img.complete ? null : new Promise((done) => {
    img.addEventListener('load', done, {once: true}); img.addEventListener('error', done, {once: true});
    setTimeout(done, 10000);
  })));
}
"""


@dataclass
class Finding:
    page: str
    kind: str
    detail: str

    def __str__(self):
        return f"{self.page}: {self.kind}: {self.detail}"


@dataclass
class SiteReport:
    pages: int = 0
    findings: list = field(default_factory=list)
    screenshots: list = field(default_factory=list)
    seconds: float = 0.0
    skipped: str = ""        # why the check did not run (no Chromium)

    @property
    def failures(self):
        return self.findings

    @property
    def ok(self):
        return not self.failures and not self.skipped


def chromium_executable():
    """Debian's Chromium (or DRAKE_HYBRID_CHROMIUM); FileNotFoundError saying how to install it."""
    for candidate in (os.environ.get("DRAKE_HYBRID_CHROMIUM"), "/usr/bin/chromium", shutil.which("chromium"),
                      shutil.which("chromium-browser")):
        if candidate and Path(candidate).is_file():
            return candidate
    raise FileNotFoundError("no Chromium found; install Debian's package: apt-get install chromium")


def site_pages(site):
    """The site's HTML pages (relative paths, sorted), its static files' folders left out."""
    site = Path(site)
    return sorted(str(page.relative_to(site)) for page in site.rglob("*.html")
                  if not {"_static", "_images", "_sources"} & set(page.relative_to(site).parts))


def _excerpt(text, match, context=40):
    start, end = max(0, match.start() - context), min(len(text), match.end() + context)
    return " ".join(("..." + text[start:end] + "...").split())


def text_findings(page, text, terms=()):
    """Findings of raw markup and bookkeeping in a page's rendered text (``page`` names it);
    ``terms``: the page's definition-list terms and field names."""
    findings = []
    for kind, pattern in RAW_MARKUP + BOOKKEEPING:
        for match in pattern.finditer(text):
            findings.append(Finding(page, kind, f"{match.group(0).strip()!r} in {_excerpt(text, match)!r}"))
    for term in terms:
        if NOTE_TERMS.fullmatch(term):
            findings.append(Finding(page, "maintainers' note", f"a definition list's term {term!r}"))
    return findings


def image_findings(page, images):
    findings = []
    for image in images:
        width, height = image["natural"]
        if not image["complete"] or width == 0 or height == 0:
            findings.append(Finding(page, "broken image", f"{image['src']!r} did not load"))
        elif image["shown"] and min(image["size"]) <= 0:
            findings.append(Finding(page, "broken image", f"{image['src']!r} is shown with size {image['size']}"))
    return findings


def row_findings(page, rows, viewport):
    """A figure row's figures side by side (tops within a few pixels, no overlap), each picture shown
    with its caption under it."""
    findings, where = [], f"at {viewport['width']} px"
    for row in rows:
        if len(row) < 2:
            findings.append(Finding(page, "figure row", f"a figure-row holds {len(row)} figure(s) {where}"))
            continue
        for index, figure in enumerate(row):
            if not figure["image"] or min(figure["image"][2:]) <= 0:
                findings.append(Finding(page, "figure row", f"figure {index + 1} shows no picture {where}"))
            elif not figure["caption"]:
                findings.append(Finding(page, "figure row", f"figure {index + 1} has no caption {where}"))
            elif figure["captionBox"][1] < figure["image"][1] + figure["image"][3] - 1:
                findings.append(Finding(page, "figure row", f"figure {index + 1}'s caption is not under its picture {where}"))
        boxes = [figure["image"] for figure in row if figure["image"]]
        if len(boxes) == len(row):
            tops = [box[1] for box in boxes]
            if max(tops) - min(tops) > 4:
                findings.append(Finding(page, "figure row", f"the pictures are not side by side {where} (tops {tops})"))
            ordered = sorted(boxes)
            if any(left[0] + left[2] > right[0] + 1 for left, right in zip(ordered, ordered[1:])):
                findings.append(Finding(page, "figure row", f"the pictures overlap {where}"))
    return findings


def _api_page(pages):
    for candidate in API_PAGES:
        if candidate in pages:
            return candidate
    return next((page for page in pages if page.startswith("reference/generated/")), None)


def check_site(html_dir, screenshots=None, executable=None, pages=None):
    """Open every page of the built site ``html_dir`` in headless Chromium and check it (the module's
    docstring); screenshots of the front page and an API page go to ``screenshots`` (a folder; None:
    none). ``pages``: only these (relative paths), default every page. Returns a ``SiteReport``."""
    from playwright.sync_api import sync_playwright

    site = Path(html_dir).resolve()
    if not (site / "index.html").is_file():
        raise FileNotFoundError(f"{site} has no index.html: build the site first")
    pages = site_pages(site) if pages is None else list(pages)
    report = SiteReport(pages=len(pages))
    executable = executable or chromium_executable()
    api_page = _api_page(pages)
    if screenshots is not None:
        screenshots = Path(screenshots)
        screenshots.mkdir(parents=True, exist_ok=True)
    start = time.monotonic()
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=executable, headless=True, args=list(CHROMIUM_FLAGS))
        try:
            context = browser.new_context(viewport=WIDE)
            context.route("**/*", lambda route: route.continue_() if route.request.url.startswith(LOCAL_URLS)
                          else route.abort())
            page = context.new_page()
            state = {}
            page.on("pageerror", lambda error: state["errors"].append(f"JavaScript error: {error}"))
            page.on("requestfailed", lambda request: request.url.startswith("file:") and
                    state["errors"].append(f"missing file {request.url[len(site.as_uri()) + 1:]!r}"))
            for name in pages:
                state["errors"] = []
                page.set_viewport_size(WIDE)
                try:
                    page.goto((site / name).as_uri(), wait_until="load", timeout=30000)
                    page.evaluate(_LOAD_IMAGES)
                    probe = page.evaluate(_PROBE)
                except Exception as error:           # a page that does not load is a finding, not a crash
                    report.findings.append(Finding(name, "page did not load", str(error).splitlines()[0]))
                    continue
                report.findings += text_findings(name, f"{probe['title']}\n{probe['text']}", probe["terms"])
                report.findings += image_findings(name, probe["images"])
                report.findings += [Finding(name, "page error", error) for error in state["errors"]]
                if probe["rows"]:
                    report.findings += row_findings(name, probe["rows"], WIDE)
                    page.set_viewport_size(NARROW)
                    report.findings += row_findings(name, page.evaluate(_PROBE)["rows"], NARROW)
                if screenshots is not None and name in ("index.html", api_page):
                    stem = "front_page" if name == "index.html" else "api_page"
                    for viewport, suffix in ((WIDE, "wide"), (NARROW, "narrow")):
                        page.set_viewport_size(viewport)
                        path = screenshots / f"{stem}_{suffix}.png"
                        page.screenshot(path=str(path), full_page=name == "index.html")
                        report.screenshots.append(path)
        finally:
            browser.close()
    report.seconds = time.monotonic() - start
    return report


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("site", nargs="?", default="docs/_build/html", help="the built site (default: %(default)s)")
    parser.add_argument("--screenshots", default=None,
                        help="folder of the screenshots (default: screenshots/ next to the site)")
    args = parser.parse_args(argv)
    site = Path(args.site)
    if not (site / "index.html").is_file():
        print(f"{site} has no index.html: build the site first", file=sys.stderr)
        return 2
    try:
        executable = chromium_executable()
    except FileNotFoundError as error:
        if os.environ.get("DRAKE_HYBRID_REQUIRE_BROWSER") == "1":
            print(f"site check: {error}", file=sys.stderr)
            return 2
        print(f"site check skipped: {error}")
        return 0
    screenshots = Path(args.screenshots) if args.screenshots else site.parent / "screenshots"
    report = check_site(site, screenshots=screenshots, executable=executable)
    for finding in report.findings:
        print(finding)
    print(f"site check: {report.pages} pages in headless Chromium in {report.seconds:.0f} s: "
          f"{len(report.failures)} failures; "
          f"screenshots in {screenshots}")
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
