"""Rewrite recorded report pages with the compact clickable heatmaps of today's explorer.

Pages written before the explorer carried its cells as JSON held one ``<rect>`` element of
about 330 bytes per filled cell (4.9 MB for 27 runs). This rewrites each ``report.html``
in place: every heatmap's rectangles become the JSON that
:func:`qdil.evaluation.explorer.archive_svg` writes, and the page's script becomes today's,
which draws them. Nothing else on the page changes; a page already compact is left alone::

    python benchmarks/probes/compact_pages.py docs/reports/*/report.html
"""

from __future__ import annotations

import argparse
import html
import re
from pathlib import Path

from qdil.evaluation.explorer import _SCRIPT, archive_svg

SVG = re.compile(
    r'<svg class="archive" viewBox="0 0 ([\d.]+) ([\d.]+)" role="img" aria-label="([^"]*)">'
    r'<image href="([^"]*)" width="[\d.]+" height="[\d.]+"/>(.*?)</svg>',
    re.S,
)
RECT = re.compile(r"<rect ([^>]*)><title>.*?</title></rect>", re.S)
ATTRIBUTE = re.compile(r'([\w-]+)="([^"]*)"')
PANEL = re.compile(r'<div class="elite" id="([^"]+)"')
SCRIPT = re.compile(r"<script>.*?</script>", re.S)
SUFFIX = ": archive heatmap, click a cell"


def compact(page: str) -> str:
    """The page with JSON cells and today's script (unchanged if it has them already)."""
    if 'class="cells"' in page or "<rect " not in page:
        return page

    def rewrite(match: re.Match[str]) -> str:
        width, height, label, png, rects = match.groups()
        title = html.unescape(label).removesuffix(SUFFIX)
        cells, panel = [], None
        for attributes in RECT.findall(rects):
            a = {k: html.unescape(v) for k, v in ATTRIBUTE.findall(attributes)}
            panel = a["data-panel"]
            entry = [float(a["x"]), float(a["y"]), float(a["width"]), float(a["height"])]
            entry += [a["data-cell"], a["data-ret"], a["data-measures"]]
            if "data-video" in a:
                entry += [a["data-video"], a["data-episode"]]
            cells.append(entry)
        if panel is None:  # an empty archive: the panel of the table it sits in
            panel = PANEL.search(page, match.end()).group(1)
        return archive_svg(title, html.unescape(png), float(width), float(height), panel, cells)

    page = SVG.sub(rewrite, page)
    return SCRIPT.sub(lambda _: f"<script>{_SCRIPT}</script>", page, count=1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pages", nargs="+", type=Path, help="report.html files")
    for path in parser.parse_args().pages:
        before = path.read_text(encoding="utf-8")
        after = compact(before)
        if after != before:
            path.write_text(after, encoding="utf-8")
        print(f"{path}: {len(before.encode()):,} -> {len(after.encode()):,} bytes")


if __name__ == "__main__":
    main()
