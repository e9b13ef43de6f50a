"""The report page's clickable archives: heatmaps whose cells show their elite.

Each heatmap PNG (pyribs' ``grid_archive_heatmap``, :mod:`qdil.evaluation.figures`) sits in
an inline SVG with one transparent rectangle over every filled cell, placed from the
figure's own axes (:class:`~qdil.evaluation.figures.HeatmapGrid`); the page carries the
cells as compact JSON beside each SVG and its script draws the rectangles (a page of
thousands of cells stays small). A click on a cell shows,
under the table, the run, the cell, its return and measures and, for the cells the report
rendered (:mod:`qdil.evaluation.gallery`), the elite's video; those cells have a blue
outline. Below, one gallery row per run holds its videos. The page needs nothing online:
thirty lines of plain JavaScript, the PNGs and the MP4s beside it.
"""

from __future__ import annotations

import html
import json
from collections.abc import Mapping, Sequence
from pathlib import Path

from qdil.evaluation import document as doc
from qdil.evaluation.figures import HeatmapGrid
from qdil.evaluation.gallery import Gallery
from qdil.evaluation.runs import RunResult
from qdil.evaluation.video import Video

_STYLE = (
    ".explorer{display:flex;flex-wrap:wrap;gap:1em;align-items:flex-start}"
    "svg.archive{width:100%;min-width:240px;max-width:420px;height:auto;display:block}"
    ".cell{fill:#000;fill-opacity:0;cursor:pointer}"
    ".cell.video{stroke:#1e90ff;stroke-width:3}"
    ".cell:hover,.cell:focus{stroke:#000;stroke-width:3;outline:none}"
    ".cell.selected{stroke:#00c853;stroke-width:5}"
    ".elite{flex:1 1 320px;border:1px solid #ccc;padding:0 1em;margin:1em 0}"
    ".elite video{display:block;width:100%;max-width:480px}"
    ".gallery{display:flex;flex-wrap:wrap;gap:8px;align-items:flex-start;margin:.5em 0}"
    ".gallery figure{margin:0;font-size:80%;text-align:center}"
    ".gallery video{display:block;max-width:240px}"
)

# draws each heatmap's cells from the JSON beside it, and fills a task's panel from the
# clicked cell's data-* attributes (text only, never markup)
_SCRIPT = """
const SVG = 'http://www.w3.org/2000/svg';
function qdilCells() {
  document.querySelectorAll('script.cells').forEach(data => {
    const svg = data.previousElementSibling, d = svg.dataset;
    for (const [x, y, w, h, cell, ret, measures, video, episode] of JSON.parse(data.text)) {
      const rect = document.createElementNS(SVG, 'rect');
      const title = document.createElementNS(SVG, 'title');
      rect.setAttribute('class', video ? 'cell video' : 'cell');
      const box = {x, y, width: w, height: h, tabindex: 0};
      Object.entries(box).forEach(([k, v]) => rect.setAttribute(k, v));
      Object.assign(rect.dataset, {panel: d.panel, run: d.run, cell, ret, measures});
      if (video) Object.assign(rect.dataset, {video, episode});
      title.textContent = 'cell ' + cell + ': return ' + ret;
      rect.append(title); svg.append(rect);
    }
  });
}
if (document.readyState === 'loading') document.addEventListener('DOMContentLoaded', qdilCells);
else qdilCells();
function qdilShow(cell) {
  const d = cell.dataset, panel = document.getElementById(d.panel);
  document.querySelectorAll('.cell.selected').forEach(c => c.classList.remove('selected'));
  cell.classList.add('selected');
  const line = (text, tag) => {
    const p = document.createElement(tag || 'p'); p.textContent = text; return p; };
  panel.replaceChildren(line(d.run + ', cell ' + d.cell, 'h4'),
    line('return ' + d.ret + ' · measures (' + d.measures + ')'));
  if (d.video) {
    const video = document.createElement('video');
    Object.assign(video, {src: d.video, controls: true, muted: true, loop: true,
                          autoplay: true, playsInline: true});
    panel.append(video, line(d.episode));
    video.play().catch(() => {});
  } else {
    panel.append(line(panel.dataset.novideo));
  }
}
document.addEventListener('click', e => {
  const cell = e.target.closest('.cell'); if (cell) qdilShow(cell); });
document.addEventListener('keydown', e => {
  if (e.key === 'Enter' && e.target.matches('.cell')) qdilShow(e.target); });
// a gallery clip plays while the mouse is over it
document.addEventListener('mouseover', e => {
  if (e.target.matches('.gallery video')) e.target.play().catch(() => {}); });
document.addEventListener('mouseout', e => {
  if (e.target.matches('.gallery video')) e.target.pause(); });
"""


def _attr(value: object) -> str:
    return html.escape(str(value), quote=True)


def _cell_text(cell: Sequence[int]) -> str:
    return f"({', '.join(map(str, cell))})"


def _measures(values: Sequence[float]) -> str:
    return ", ".join(f"{m:.2f}" for m in values)


def run_title(run: RunResult) -> str:
    """How the page names a run: method and seed."""
    return f"{run.method} · seed {run.seed}"


def heatmap_svg(
    run: RunResult, png: str, grid: HeatmapGrid, panel: str, videos: Sequence[Video], out: Path
) -> str:
    """One run's heatmap with a clickable rectangle over every filled cell.

    Args:
        run: the run (its light archive gives each cell's return and measures).
        png: the heatmap PNG, relative to the page.
        grid: where the PNG draws the cells.
        panel: id of the element that shows a clicked cell.
        videos: the run's videos (their cells get a video and an outline).
        out: the report folder (videos' paths are made relative to it).
    """
    assert run.archive is not None  # every included run has its final archive
    data = run.archive.data(["index", "objective", "measures"])
    by_cell = {video.cell: video for video in videos}
    cells = []
    for cell, value, measures in zip(
        run.archive.int_to_grid_index(data["index"]), data["objective"], data["measures"],
        strict=True,
    ):  # fmt: skip
        key = tuple(int(i) for i in cell)
        x, y, w, h = grid.box(key)
        entry = [round(x, 1), round(y, 1), round(w, 1), round(h, 1), _cell_text(key)]
        entry += [f"{value:,.1f}", _measures(measures)]
        video = by_cell.get(key)
        if video is not None:
            entry += [
                video.path.relative_to(out).as_posix(),
                f"The video: one deterministic episode, {video.steps} steps, return "
                f"{video.episode_return:,.1f}, measures ({_measures(video.measures)}).",
            ]
        cells.append(entry)
    return archive_svg(run_title(run), png, grid.width, grid.height, panel, cells)


def archive_svg(
    title: str, png: str, width: float, height: float, panel: str, cells: list[list]
) -> str:
    """A heatmap PNG in an SVG, and its filled cells as JSON for the page's script.

    Args:
        title: the run, as the page names it.
        png: the heatmap PNG, relative to the page.
        width: the SVG's width (the PNG's pixels).
        height: its height.
        panel: id of the element that shows a clicked cell.
        cells: per filled cell ``[x, y, w, h, cell, return, measures]`` (the box in the
            PNG's pixels, then the texts the panel shows), with ``video`` (relative to the
            page) and ``episode`` (its caption) appended where the cell has a video.
    """
    label = _attr(f"{title}: archive heatmap, click a cell")
    # "</" would end the script element early: JSON allows "<\/" for it
    payload = json.dumps(cells, ensure_ascii=False, separators=(",", ":")).replace("</", "<\\/")
    return (
        f'<svg class="archive" viewBox="0 0 {width:g} {height:g}" role="img" '
        f'aria-label="{label}" data-panel="{_attr(panel)}" data-run="{_attr(title)}">'
        f'<image href="{_attr(png)}" width="{width:g}" height="{height:g}"/></svg>'
        f'<script type="application/json" class="cells">{payload}</script>'
    )


def task_blocks(
    number: int,
    runs_by_method: Mapping[str, Sequence[RunResult]],
    heatmaps: Mapping[Path, str],
    grids: Mapping[Path, HeatmapGrid],
    gallery: Gallery,
    out: Path,
    markdown: str,
) -> list[doc.Block]:
    """A task's clickable heatmaps (method rows, seed columns), its panel and its galleries.

    Args:
        number: the task's place on the page (makes the panel's id).
        runs_by_method: the task's runs.
        heatmaps: run directory -> heatmap PNG, relative to ``out``.
        grids: run directory -> where that PNG draws the cells.
        gallery: the report's videos.
        out: the report folder.
        markdown: what stands for the heatmaps in ``report.md`` (the image table).
    """
    panel = f"elite-{number}"

    def videos(run: RunResult) -> list[Video]:
        return gallery.videos.get(run.path, [])

    width = max(len(runs) for runs in runs_by_method.values())
    head = "".join(f"<th>run {i + 1}</th>" for i in range(width))
    rows = []
    for method, runs in runs_by_method.items():
        cells = [
            heatmap_svg(r, heatmaps[r.path], grids[r.path], panel, videos(r), out)
            if r.path in grids
            else "–"
            for r in runs
        ]
        cells += [""] * (width - len(cells))
        rows.append(f"<tr><td>{_attr(method)}</td>{''.join(f'<td>{c}</td>' for c in cells)}</tr>")
    no_video = (
        "No video of this cell: the report rendered "
        f"{gallery.settings.count} per run (qdil report --videos K), or run "
        "qdil render RUN_DIR --cell I J."
    )
    blocks = [
        doc.raw(
            f'<div class="explorer"><table><tr><th>Method</th>{head}</tr>{"".join(rows)}</table>'
            f'<div class="elite" id="{panel}" data-novideo="{_attr(no_video)}">'
            "<p>Click a cell of a heatmap: its elite's return and measures, and its video "
            "where it has one (blue outline).</p></div></div>",
            markdown,
        )
    ]
    runs = [run for rs in runs_by_method.values() for run in rs if gallery.videos.get(run.path)]
    if runs:
        rows_html = "".join(_gallery_row(run, gallery.videos[run.path], out) for run in runs)
        items = [_gallery_markdown(run, gallery.videos[run.path], out) for run in runs]
        blocks += [doc.heading("Gaits", 4)]
        blocks += [doc.raw(rows_html, "\n".join(f"- {item}" for item in items))]
    return blocks


def _gallery_row(run: RunResult, videos: Sequence[Video], out: Path) -> str:
    # "#t=1": each clip shows a frame one second in (a stride, not the reset pose)
    figures = "".join(
        f'<figure><video src="{_attr(v.path.relative_to(out).as_posix())}#t=1" controls muted '
        f'loop playsinline preload="metadata"></video><figcaption>cell {_cell_text(v.cell)}'
        f" · return {v.episode_return:,.1f}<br>measures ({_measures(v.measures)})"
        "</figcaption></figure>"
        for v in videos
    )
    return f'<p>{_attr(run_title(run))}</p><div class="gallery">{figures}</div>'


def _gallery_markdown(run: RunResult, videos: Sequence[Video], out: Path) -> str:
    links = ", ".join(
        f"[cell {_cell_text(v.cell)}]({v.path.relative_to(out).as_posix()})" for v in videos
    )
    return f"{run_title(run)}: {links}"


def videos_text(gallery: Gallery) -> str:
    """What the page says about its videos: how they were made, or why there are none."""
    s = gallery.settings
    if gallery.reason:
        return f"No videos: {gallery.reason}."
    if not gallery.count:
        return "No videos: no run's archive has an elite to replay."
    return (
        f"Videos: {s.count} elites per run ({gallery.count} in all), spread over the archive "
        "by farthest-point sampling in measure space from the best; each plays one "
        "deterministic episode as `qdil eval` and `qdil render` replay it "
        f"({s.width}×{s.height} MP4, {gallery.seconds:.0f} s to make). A heatmap cell's "
        "return and measures are the archive's, which may differ from the episode's."
    )


def script_block() -> doc.Block:
    """The page's style and script for the clickable heatmaps (once per page)."""
    return doc.raw(f"<style>{_STYLE}</style><script>{_SCRIPT}</script>")
