"""The pieces every sdnn page is made of: one self-contained HTML5 document (style inline, figures as base64
PNGs, the chart as inline SVG; nothing loaded from elsewhere), text from charts and files HTML-escaped.
"""

from __future__ import annotations

import base64
import html
from collections.abc import Sequence
from pathlib import Path

from ..analysis.drawing import chart_svg
from ..atomic import atomic_write_text
from .canvas import png_bytes

__all__ = ["esc", "page", "table", "figure", "section", "paragraph", "chart_section", "write_html"]

_STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 0 auto; padding: 1em 2em;
       max-width: 1200px; color: #222; line-height: 1.4; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; } h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; }
.sub { color: #555; margin-top: 0; }
.scroll { overflow-x: auto; max-width: 100%; }
table { border-collapse: collapse; margin: 0.5em 0 1em; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.6em; text-align: right; white-space: nowrap; }
th { background: #f0f0f0; } td.l, th.l { text-align: left; }
figure { margin: 0.5em 0 1.5em; } figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { color: #555; font-size: 0.9em; }
.warn { background: #fff4d6; border-left: 4px solid #e0a000; padding: 0.4em 0.8em; margin: 0.3em 0; }
.ok { background: #e8f6e8; border-left: 4px solid #3a3; padding: 0.4em 0.8em; margin: 0.3em 0; }
code { background: #f4f4f4; padding: 0 0.2em; }
.diagram svg { max-width: 100%; height: auto; }
"""

esc = html.escape


def page(title: str, parts: Sequence[str], subtitle: str = "") -> str:
    """A whole HTML5 document: `title` as heading, `parts` (HTML fragments) in order, the style inline."""
    head = f"<h1>{esc(title)}</h1>" + (f'\n<p class="sub">{esc(subtitle)}</p>' if subtitle else "")
    body = "\n".join([head, *parts])
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">\n<title>{esc(title)}</title>\n'
            f"<style>{_STYLE}</style>\n</head>\n<body>\n{body}\n</body>\n</html>\n")


def section(title: str, parts: Sequence[str], anchor: str = "") -> str:
    ident = f' id="{esc(anchor)}"' if anchor else ""
    return f"<section{ident}>\n<h2>{esc(title)}</h2>\n" + "\n".join(parts) + "\n</section>"


def paragraph(text: str, kind: str = "") -> str:
    return f'<p class="{kind}">{esc(text)}</p>' if kind else f"<p>{esc(text)}</p>"


def _cell(value, digits: int) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


def table(headers: Sequence[str], rows: Sequence[Sequence], left: int = 1, digits: int = 6) -> str:
    """An HTML table; the first `left` columns are left-aligned (names), numbers shown to `digits` digits."""
    def cells(row, tag):
        return "".join(f'<{tag}{" class=l" if i < left else ""}>{esc(_cell(v, digits))}</{tag}>'
                       for i, v in enumerate(row))

    body = "\n".join(f"<tr>{cells(r, 'td')}</tr>" for r in rows)
    return f'<div class="scroll"><table>\n<tr>{cells(headers, "th")}</tr>\n{body}\n</table></div>'


def figure(fig, caption: str, alt: str | None = None, dpi: float = 80) -> str:
    """A matplotlib figure as an embedded PNG with a caption (`dpi` 80 keeps a page of figures small)."""
    data = base64.b64encode(png_bytes(fig, dpi)).decode("ascii")
    return (f'<figure><img src="data:image/png;base64,{data}" alt="{esc(alt or caption)}">'
            f"<figcaption>{esc(caption)}</figcaption></figure>")


def chart_section(diagram, highlight=(), title: str = "The chart") -> str:
    """The chart as a block diagram (inline SVG: the page stays one file), highlighted blocks in orange."""
    svg = chart_svg(diagram, highlight)
    return section(title, ['<div class="diagram">' + svg + "</div>"], "chart")


def write_html(path: str | Path, text: str) -> Path:
    """Write a page atomically: a reader sees the old file or the whole new one."""
    atomic_write_text(path, text)
    return Path(path)
