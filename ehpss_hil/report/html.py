"""``report.html``: the lines of ``report.md`` as one self-contained page (figures embedded as
base64 PNG, styles inline), to mail or archive as one file. Converts only the Markdown the
report writer produces: headings, bullet lists, tables, images (with the italic caption line
under them as a ``<figcaption>``), paragraphs, `code`, **bold**.
"""

from __future__ import annotations

import base64
import html
import re
from pathlib import Path

_STYLE = """
body { font: 15px/1.45 system-ui, sans-serif; max-width: 1150px; margin: 2em auto; color: #222; }
table { border-collapse: collapse; margin: 0.6em 0; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: left; font-variant-numeric: tabular-nums; }
th { background: #f2f2f2; }
figure { margin: 1em 0; }
figcaption { color: #444; font-size: 14px; }
img { max-width: 100%; border: 1px solid #ddd; margin: 0.5em 0; }
code { background: #f4f4f4; padding: 0 3px; }
"""
_IMAGE = re.compile(r"^!\[([^\]]*)\]\(([^)]+)\)\s*$")
_CAPTION = re.compile(r"^\*([^*].*)\*\s*$")


def _inline(text: str) -> str:
    t = html.escape(text, quote=False)
    t = re.sub(r"`([^`]+)`", r"<code>\1</code>", t)
    return re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", t)


def _image(alt: str, src: str, base: Path, caption: str = "") -> str:
    path = base / src
    try:
        data = base64.b64encode(path.read_bytes()).decode("ascii")
    except OSError:
        return f"<p>(figure {html.escape(src)} missing)</p>"
    cap = f"<figcaption>{_inline(caption)}</figcaption>" if caption else ""
    return f'<figure><img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">{cap}</figure>'


def _table(rows: list[str]) -> str:
    cells = [[c.strip() for c in r.strip().strip("|").split("|")] for r in rows]
    head, body = cells[0], [c for c in cells[1:] if not all(set(x) <= {"-", ":"} for x in c)]
    out = ["<table><tr>" + "".join(f"<th>{_inline(c)}</th>" for c in head) + "</tr>"]
    out += ["<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in r) + "</tr>" for r in body]
    return "\n".join(out) + "</table>"


def markdown_to_html(lines: list[str], base: Path) -> str:
    """The body HTML of the report's Markdown ``lines`` (images read relative to ``base``)."""
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i].rstrip("\n")
        if line.startswith("|"):
            j = i
            while j < len(lines) and lines[j].startswith("|"):
                j += 1
            out.append(_table(lines[i:j]))
            i = j
            continue
        if line.startswith("- "):
            j = i
            items = []
            while j < len(lines) and lines[j].startswith("- "):
                items.append(f"<li>{_inline(lines[j][2:])}</li>")
                j += 1
            out.append("<ul>" + "".join(items) + "</ul>")
            i = j
            continue
        if m := _IMAGE.match(line):
            cap = _CAPTION.match(lines[i + 1].rstrip("\n")) if i + 1 < len(lines) else None
            out.append(_image(m.group(1), m.group(2), base, cap.group(1) if cap else ""))
            i += 2 if cap else 1
            continue
        elif line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            out.append(f"<h{level}>{_inline(line[level:].strip())}</h{level}>")
        elif line.strip():
            out.append(f"<p>{_inline(line)}</p>")
        i += 1
    return "\n".join(out)


def write_html(lines: list[str], base: Path, path: Path, title: str) -> Path:
    """Write the self-contained ``path`` from the report's Markdown ``lines``."""
    page = (
        f'<!doctype html>\n<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>'
        f"<style>{_STYLE}</style></head><body>\n{markdown_to_html(lines, base)}\n</body></html>\n"
    )
    path.write_text(page, encoding="utf-8")
    return path
