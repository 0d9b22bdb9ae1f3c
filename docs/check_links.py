"""Check the built site's internal links, offline: every relative href and src of every page.

    python docs/check_links.py docs/_build/html

A link to a file of the site must find the file, and a '#anchor' an element with that id in it
(external links, http(s) and mailto, are not fetched: CI and this machine have no network). Prints
each broken link with the page it is on and exits 1 if there is one.
"""

import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit


class _Links(HTMLParser):
    def __init__(self):
        super().__init__()
        self.links, self.ids = [], set()

    def handle_starttag(self, tag, attributes):
        attributes = dict(attributes)
        if attributes.get("id"):
            self.ids.add(attributes["id"])
        if tag == "a" and attributes.get("name"):
            self.ids.add(attributes["name"])
        for key in ("href", "src"):
            if attributes.get(key) and not (tag == "link" and key == "href" and "stylesheet" not in
                                            (attributes.get("rel") or "")):
                self.links.append(attributes[key])


def parse(page, cache={}):
    if page not in cache:
        parser = _Links()
        parser.feed(page.read_text(errors="replace"))
        cache[page] = parser
    return cache[page]


def broken_links(site):
    site = Path(site)
    broken = []
    for page in sorted(site.rglob("*.html")):
        if "_static" in page.parts:
            continue
        for link in parse(page).links:
            parts = urlsplit(link)
            if parts.scheme or link.startswith(("//", "data:", "javascript:")):
                continue
            target = (page.parent / unquote(parts.path)).resolve() if parts.path else page
            if target.is_dir():
                target = target / "index.html"
            if not target.exists():
                broken.append((page.relative_to(site), link, "no such file"))
            elif parts.fragment and target.suffix == ".html" and unquote(parts.fragment) not in parse(target).ids:
                broken.append((page.relative_to(site), link, "no such anchor"))
    return broken


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    site = Path(argv[0] if argv else "docs/_build/html")
    if not (site / "index.html").exists():
        sys.exit(f"{site} has no index.html: build the site first")
    broken = broken_links(site)
    for page, link, why in broken:
        print(f"{page}: {link} ({why})")
    pages = sum(1 for _ in site.rglob("*.html"))
    print(f"internal links of {pages} pages: {len(broken)} broken")
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
