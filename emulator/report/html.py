"""Self-contained HTML reports: ``report.html`` beside every ``report.md``.

One page, no external resource: the report's markdown (headings, paragraphs, lists,
tables, code, links) rendered to HTML, every figure of the folder embedded as a base64
``data:`` URI, and optional contact sheets (images in a grid, each labelled). A browser
opened on the file alone shows everything; nothing is fetched.

:func:`write_report` writes ``report.md`` and ``report.html`` together and is what every
report writer calls.  :func:`contact_sheet` lays out thumbnails; :func:`run_contact_sheet`
builds the sheet of a run folder: each method's emulated left frames over sampled cycles,
labelled with the exposure and the saturated fraction.
"""

from __future__ import annotations

import base64
import html
import os
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from emulator.io.files import REPORT_FILE, write_text, read_bytes
from emulator.io.png import encode_png, read_image
from emulator.io.runfolder import read_run_json, read_tables

__all__ = ["HTML_REPORT_FILE", "Thumb", "markdown_to_html", "png_data_uri", "thumbnail", "contact_sheet",
           "render_page", "write_report", "run_contact_sheet", "run_folder_pages",
           "spread_indices"]

#: File name of the HTML report, beside ``report.md``.
HTML_REPORT_FILE = "report.html"
#: Width of a contact-sheet thumbnail, pixels.
THUMB_WIDTH_PX = 240

_STYLE = """
body{font-family:system-ui,sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;color:#222;line-height:1.45}
h1,h2,h3{line-height:1.2}table{border-collapse:collapse;margin:1em 0;font-size:.92em}
td,th{border:1px solid #ccc;padding:.25em .6em;text-align:left}th{background:#f3f3f3}
td.num{text-align:right;font-variant-numeric:tabular-nums}code{background:#f4f4f4;padding:0 .2em}
pre{background:#f4f4f4;padding:.6em;overflow-x:auto}img{max-width:100%}
figure{margin:1em 0}.sheet{display:grid;gap:6px;align-items:start}
.sheet figure{margin:0}.sheet img{width:100%;image-rendering:auto;border:1px solid #ddd}
.sheet figcaption{font-size:.75em;color:#444}.rowlabel{font-weight:600;font-size:.85em;align-self:center}
.ci{color:#777;font-size:.85em;white-space:nowrap}
"""


@dataclass(frozen=True)
class Thumb:
    """One contact-sheet cell: 8-bit image (H, W) grey or (H, W, 3) BGR, and its caption."""

    image: np.ndarray | None
    caption: str


def png_data_uri(data: bytes) -> str:
    """``data:image/png;base64,...`` of PNG bytes."""
    if not data.startswith(b"\x89PNG\r\n\x1a\n"):
        raise ValueError("png_data_uri needs PNG bytes")
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def thumbnail(image: np.ndarray, *, white_level: int | None = None, width_px: int = THUMB_WIDTH_PX) -> np.ndarray:
    """A viewable 8-bit thumbnail of a saved image, at most ``width_px`` wide (never enlarged).

    ``uint16`` (12-bit Bayer DN): each 2x2 Bayer block averaged to one grey pixel, scaled
    by ``white_level`` and gamma-encoded (1/2.2); ``uint8`` grey or BGR: resized as is.
    """
    import cv2

    image = np.asarray(image)
    if image.dtype == np.uint16:
        h, w = (image.shape[0] // 2) * 2, (image.shape[1] // 2) * 2
        block = image[:h, :w].astype(np.float32).reshape(h // 2, 2, w // 2, 2).mean(axis=(1, 3))
        top = float(white_level or max(int(image.max()), 1))
        image = np.round(255.0 * np.clip(block / top, 0.0, 1.0) ** (1 / 2.2)).astype(np.uint8)
    elif image.dtype != np.uint8:
        raise ValueError(f"thumbnail needs a uint8 or uint16 image, got {image.dtype}")
    if image.shape[1] <= width_px:  # never enlarged: the page scales it, the file stays small
        return np.ascontiguousarray(image)
    scale = width_px / image.shape[1]
    size = (width_px, max(1, round(image.shape[0] * scale)))
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA)


def _encode(image: np.ndarray) -> bytes:
    return encode_png(np.ascontiguousarray(image), "thumbnail")


def contact_sheet(rows: Sequence[tuple[str, Sequence[Thumb]]], *, title: str | None = None) -> str:
    """HTML of a grid: one row per label, its thumbnails in order (a cell without image shows its caption)."""
    if not rows:
        return ""
    ncols = max(len(cells) for _, cells in rows)
    out = [f"<h2>{html.escape(title)}</h2>" if title else "",
           f'<div class="sheet" style="grid-template-columns:8em repeat({ncols},1fr)">']
    for label, cells in rows:
        out.append(f'<div class="rowlabel">{html.escape(label)}</div>')
        for cell in cells:
            caption = html.escape(cell.caption)
            if cell.image is None:
                out.append(f"<figure><figcaption>{caption}</figcaption></figure>")
            else:
                uri = png_data_uri(_encode(cell.image))
                out.append(f'<figure><img src="{uri}" alt="{caption}"><figcaption>{caption}</figcaption></figure>')
        out.extend("<div></div>" for _ in range(ncols - len(cells)))
    out.append("</div>")
    return "\n".join(out)


# ---------------------------------------------------------------------------- markdown subset
#: A number, optionally with a unit and an interval: ``1.23``, ``32.8 %``, ``1.23 [0.98, 1.51]``,
#: ``0.41 (0.30..0.52)``; such cells are right-aligned, the interval in a lighter type.
_NUM = re.compile(r"^[-+]?(\d[\d ,.]*%?|\d*\.\d+%?|nan|inf)( ?[a-z%/]{0,8})?(?P<ci> ?(\[[^\]]*\]|\([^)]*\)))?$",
                  re.IGNORECASE)


def _inline(text: str, images: dict[str, str]) -> str:
    """Inline markdown: code, images (embedded when known), links, bold, italics; everything else escaped."""
    parts = re.split(r"(`[^`]+`)", text)
    out = []
    for part in parts:
        if part.startswith("`") and part.endswith("`") and len(part) > 1:
            out.append(f"<code>{html.escape(part[1:-1])}</code>")
            continue
        s = html.escape(part, quote=False)

        def image(m):
            alt, src = m.group(1), html.unescape(m.group(2))
            uri = images.get(src)
            if uri is None:
                return f"<em>[figure {html.escape(src)} not found]</em>"
            return f'<img src="{uri}" alt="{html.escape(alt)}">'

        s = re.sub(r"!\[([^\]]*)\]\(([^)\s]+)\)", image, s)
        s = re.sub(r"(?<!!)\[([^\]]+)\]\(([^)\s]+)\)",
                   lambda m: f'<a href="{html.escape(html.unescape(m.group(2)))}">{m.group(1)}</a>', s)
        s = re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", s)
        s = re.sub(r"(?<![\w*])\*([^*\s][^*]*)\*(?![\w*])", r"<em>\1</em>", s)
        out.append(s)
    return "".join(out)


def _table(lines: list[str], images: dict[str, str]) -> str:
    def cells(line: str) -> list[str]:
        return [c.strip() for c in line.strip().strip("|").split("|")]

    head = cells(lines[0])
    body = [cells(line) for line in lines[2:]] if len(lines) > 1 and set(lines[1].replace("|", "").strip()) <= set("-: ") \
        else [cells(line) for line in lines[1:]]
    out = ["<table><thead><tr>" + "".join(f"<th>{_inline(c, images)}</th>" for c in head) + "</tr></thead><tbody>"]
    def cell(c: str) -> str:
        m = _NUM.match(c)
        if not m:
            return f"<td>{_inline(c, images)}</td>"
        if m.group("ci"):
            value, ci = c[:m.start("ci")].rstrip(), m.group("ci").strip()
            return f'<td class="num">{_inline(value, images)} <span class="ci">{html.escape(ci)}</span></td>'
        return f'<td class="num">{_inline(c, images)}</td>'

    for row in body:
        out.append("<tr>" + "".join(cell(c) for c in row) + "</tr>")
    out.append("</tbody></table>")
    return "\n".join(out)


def markdown_to_html(text: str, images: dict[str, str] | None = None) -> str:
    """HTML of the markdown the reports write (headings, paragraphs, lists, tables, fenced code, images).

    ``images`` maps a file name used in ``![alt](name)`` to its data URI.

    >>> markdown_to_html("# T\\n\\nSome *x* and `y`.\\n\\n| a | b |\\n| --- | ---: |\\n| q | 1.5 |\\n")
    '<h1>T</h1>\\n<p>Some <em>x</em> and <code>y</code>.</p>\\n<table><thead><tr><th>a</th><th>b</th></tr></thead><tbody>\\n<tr><td>q</td><td class="num">1.5</td></tr>\\n</tbody></table>'
    """
    images = images or {}
    lines = text.splitlines()
    out: list[str] = []
    para: list[str] = []
    i = 0

    def flush():
        if para:
            out.append("<p>" + _inline(" ".join(para), images) + "</p>")
            para.clear()

    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        if stripped.startswith("```"):
            flush()
            j = i + 1
            while j < len(lines) and not lines[j].strip().startswith("```"):
                j += 1
            out.append("<pre><code>" + html.escape("\n".join(lines[i + 1:j])) + "</code></pre>")
            i = j + 1
            continue
        m = re.match(r"^(#{1,6})\s+(.*)$", stripped)
        if m:
            flush()
            n = len(m.group(1))
            out.append(f"<h{n}>{_inline(m.group(2), images)}</h{n}>")
        elif stripped.startswith("|"):
            flush()
            j = i
            while j < len(lines) and lines[j].strip().startswith("|"):
                j += 1
            out.append(_table(lines[i:j], images))
            i = j
            continue
        elif re.match(r"^[-*]\s+", stripped):
            flush()
            items = []
            j = i
            while j < len(lines) and (re.match(r"^\s*[-*]\s+", lines[j]) or (lines[j].startswith("  ") and items)):
                if re.match(r"^\s*[-*]\s+", lines[j]):
                    items.append(re.sub(r"^\s*[-*]\s+", "", lines[j]))
                else:
                    items[-1] += " " + lines[j].strip()
                j += 1
            out.append("<ul>" + "".join(f"<li>{_inline(t, images)}</li>" for t in items) + "</ul>")
            i = j
            continue
        elif not stripped:
            flush()
        else:
            para.append(stripped)
        i += 1
    flush()
    return "\n".join(out)


def render_page(title: str, body: str) -> str:
    """A complete HTML document (inline style, no external resource)."""
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<meta name=\"viewport\" content=\"width=device-width,initial-scale=1\"><title>{html.escape(title)}</title>"
            f"<style>{_STYLE}</style></head><body>\n{body}\n</body></html>\n")


def _figures(folder: Path, names: Iterable[str] | None) -> dict[str, str]:
    if names is None:
        names = sorted(p.name for p in folder.glob("*.png"))
    return {name: png_data_uri(read_bytes(folder / name)) for name in names if (folder / name).is_file()}


def write_report(folder: str | os.PathLike, markdown: str, *,
                 figures: Iterable[str] | Mapping[str, str] | None = None,
                 sheets: Sequence[str] = (), title: str | None = None) -> tuple[Path, Path]:
    """Write ``report.md`` and the self-contained ``report.html`` of ``folder``; returns both paths.

    ``figures``: PNG files of ``folder`` to embed (default: every ``*.png`` in it), or a mapping
    of those files to their captions; those the markdown shows with ``![...](name)`` appear
    there, the others after the text under "Figures", captioned (by the file name when no
    caption is given).  ``sheets``: HTML of contact sheets (:func:`contact_sheet`), placed
    after the first section of the text.
    """
    folder = Path(folder)
    captions = dict(figures) if isinstance(figures, Mapping) else {}
    md_path = write_text(folder / REPORT_FILE, markdown)
    shown = list(dict.fromkeys(re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", markdown)))
    uris = _figures(folder, None if figures is None else [*figures, *shown])
    uris.update(_figures(folder, [name for name in shown if name not in uris]))
    body = markdown_to_html(markdown, uris)
    rest = [name for name in uris if name not in shown]
    if sheets:
        sheet_html = "\n".join(s for s in sheets if s)
        cut = body.find("<h2>")
        body = body + "\n" + sheet_html if cut < 0 else body[:cut] + sheet_html + "\n" + body[cut:]
    if rest:
        body += "\n<h2>Figures</h2>\n" + "\n".join(
            f'<figure><img src="{uris[name]}" alt="{html.escape(captions.get(name, name))}"><figcaption>'
            f"{html.escape(captions.get(name, name))}</figcaption></figure>" for name in rest)
    if title is None:
        m = re.search(r"^#\s+(.*)$", markdown, re.MULTILINE)
        title = m.group(1).strip() if m else folder.name
    html_path = write_text(folder / HTML_REPORT_FILE, render_page(title, body))
    return md_path, html_path


# ---------------------------------------------------------------------------- run folders
def spread_indices(n: int, k: int) -> list[int]:
    """``k`` indices spread evenly over ``range(n)``, first and last included.

    >>> spread_indices(10, 4), spread_indices(3, 6), spread_indices(0, 3)
    ([0, 3, 6, 9], [0, 1, 2], [])
    """
    if n <= 0:
        return []
    if n <= k:
        return list(range(n))
    return sorted({round(i * (n - 1) / (k - 1)) for i in range(k)})


def run_contact_sheet(run_dir: str | os.PathLike, methods: Sequence[str], tables: dict, *, white_level: int | None,
                      n_cycles: int = 6, camera: str = "left") -> str:
    """The contact sheet of a run folder: per method, its emulated ``camera`` frames over sampled cycles.

    ``tables``: per method, the columns of its ``exposures.csv``
    (:func:`emulator.io.runfolder.read_tables`: ``cycle``, ``timestamp_ns``, ``target_ms``,
    ``bracket_ms``, ``saturated_fraction``).  A run saved
    with ``--save none`` has no images: the sheet says so.
    """
    run_dir = Path(run_dir)
    rows = []
    any_image = False
    for name in methods:
        cols = tables.get(name) or {}
        n = len(cols.get("cycle", ()))
        cells = []
        for idx in spread_indices(n, n_cycles):
            row = {key: values[idx] for key, values in cols.items()}
            sat = float(row["saturated_fraction"]) * 100.0
            caption = (f"cycle {int(row['cycle'])}: {float(row['target_ms']):.2f} ms "
                       f"(from {float(row['bracket_ms']):g} ms), {sat:.1f} % saturated")
            path = run_dir / name / "images" / camera / f"{int(row['timestamp_ns'])}.png"
            image = None
            if path.is_file():
                image = thumbnail(read_image(path), white_level=white_level)
                any_image = True
            cells.append(Thumb(image, caption))
        rows.append((name, cells))
    if not any_image:
        return ("<h2>What each method saw</h2>\n<p>No images in this run folder (it was run with "
                "<code>--save none</code>); run with <code>--save png8</code> or <code>--save png16</code> to see "
                "each method's emulated frames here.</p>")
    return contact_sheet(rows, title=f"What each method saw ({camera} camera, emulated, sampled cycles)")


def run_folder_pages(out: str | os.PathLike, folders: Sequence[tuple[str, str | os.PathLike]], *,
                     n_sheets: int = 1) -> str:
    """HTML for a report over several run folders: a link to each one's ``report.html`` and the
    contact sheets of the first ``n_sheets`` of them (every page stays a few MB at most)."""
    out = Path(out).resolve()
    folders = [(label, Path(folder)) for label, folder in folders if (Path(folder) / HTML_REPORT_FILE).is_file()]
    if not folders:
        return ""
    items = []
    for label, folder in folders:
        target = folder.resolve()
        href = (target.relative_to(out) if target.is_relative_to(out) else target) / HTML_REPORT_FILE
        items.append(f'<li><a href="{html.escape(href.as_posix())}">{html.escape(label)}</a></li>')
    parts = ["<h2>Run folders</h2>\n<ul>" + "".join(items) + "</ul>"]
    for label, folder in folders[:max(int(n_sheets), 0)]:
        info = read_run_json(folder)
        sheet = run_contact_sheet(folder, info["methods"], read_tables(folder, info["methods"]),
                                  white_level=info.get("white_level"))
        parts.append(sheet.replace("What each method saw", f"What each method saw on {html.escape(label)}", 1))
    return "\n".join(parts)
