"""Read an HTML report as a browser's parser does (html.parser) and check it is self-contained."""

from __future__ import annotations

import base64
from html.parser import HTMLParser
from pathlib import Path


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.images: list[dict] = []
        self.refs: list[str] = []
        self.tags: list[str] = []
        self.text: list[str] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.append(tag)
        if tag == "img":
            self.images.append(a)
        for key in ("src", "href"):
            if key in a and tag != "img":
                self.refs.append(a[key])
        if tag in ("script", "link", "iframe", "object", "embed"):
            self.refs.append(f"<{tag}>")

    def handle_data(self, data):
        self.text.append(data)


def read_page(path: Path) -> tuple[list[str], str]:
    """(alt text of every figure, the page's text); asserts that every image is an embedded PNG and that
    nothing is loaded from elsewhere (no scripts, links, external sources)."""
    page = _Page()
    page.feed(Path(path).read_text(encoding="utf-8"))
    page.close()
    assert page.tags[:2] == ["html", "head"], page.tags[:5]
    assert page.refs == [], page.refs
    for img in page.images:
        src = img.get("src", "")
        assert src.startswith("data:image/png;base64,"), src[:60]
        assert base64.b64decode(src.split(",", 1)[1], validate=True)[:8] == b"\x89PNG\r\n\x1a\n"
    return [img.get("alt", "") for img in page.images], " ".join(" ".join(page.text).split())
