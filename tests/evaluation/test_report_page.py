"""The report page's clickable heatmaps and videos, down to a real browser playing them.

One smoke run (one QD iteration) is reported with two 30-step videos at 96×64. Headless
Chromium (Debian's ``chromium``, driven over the DevTools pipe by ``chromium.py`` beside
this file) opens the page, clicks a cell and watches its video play. Tests that draw skip
where no OpenGL backend renders, and the browser test where no Chromium is installed,
each naming what to install.
"""

from __future__ import annotations

import html
import itertools
import json
import re
import time
from pathlib import Path

import imageio.v2 as imageio
import numpy as np
import pytest
from chromium import Chromium, find_chromium
from PIL import Image
from ribs.archives import GridArchive

from qdil.cli import main
from qdil.evaluation.gallery import VideoSettings
from qdil.evaluation.report import write_report

ROOT = Path(__file__).resolve().parents[2]
STEPS = 30
SMALL = VideoSettings(count=2, width=96, height=64, max_steps=STEPS)
SVG = re.compile(
    r'<svg class="archive" ([^>]*)>.*?</svg><script type="application/json" class="cells">'
    r"(.*?)</script>",
    re.S,
)
ATTRIBUTE = re.compile(r'([\w-]+)="([^"]*)"')
FIELDS = ("x", "y", "width", "height", "data-cell", "data-ret", "data-measures")


@pytest.fixture(scope="module")
def run_dir(smoke_run: Path) -> Path:
    """A one-iteration Walker2d smoke run with a checkpoint (conftest's)."""
    return smoke_run


@pytest.fixture(scope="module")
def page(run_dir: Path, gl: str, tmp_path_factory: pytest.TempPathFactory):
    """The report of the smoke run, with two videos."""
    out = tmp_path_factory.mktemp("report")
    return write_report([run_dir], out, records=False, videos=SMALL)


def cells_of(page_html: str) -> list[dict[str, str]]:
    """The data of every clickable cell on a page, as the page's script draws it: each
    heatmap's JSON cells with the panel and run of their SVG."""
    cells = []
    for attributes, payload in SVG.findall(page_html):
        svg = {k: html.unescape(v) for k, v in ATTRIBUTE.findall(attributes)}
        for entry in json.loads(payload):
            cell = dict(zip(FIELDS, map(str, entry), strict=False))
            if len(entry) > len(FIELDS):
                cell["data-video"], cell["data-episode"] = entry[len(FIELDS) :]
            cells.append({"data-panel": svg["data-panel"], "data-run": svg["data-run"], **cell})
    return cells


def test_the_clickable_boxes_sit_on_the_heatmaps_cells(tmp_path: Path) -> None:
    """At the centre of every cell's box the PNG is coloured where the cell is filled only."""
    import matplotlib.pyplot as plt

    from qdil.evaluation.figures import HEATMAP_DPI, heatmap_grid
    from qdil.evaluation.plots import archive_heatmap

    rng = np.random.default_rng(0)
    for dims in ([10, 10], [10]):
        archive = GridArchive(solution_dim=1, dims=dims, ranges=[(0, 1)] * len(dims))
        archive.add(np.zeros((30, 1)), rng.uniform(50, 150, 30), rng.random((30, len(dims))))
        figure = archive_heatmap(archive, title="t", vmin=0, vmax=150)
        figure.savefig(tmp_path / "h.png", dpi=HEATMAP_DPI)
        grid = heatmap_grid(figure, archive)
        plt.close(figure)
        image = np.asarray(Image.open(tmp_path / "h.png").convert("RGB"))
        assert image.shape[:2] == (grid.height, grid.width)
        filled = {tuple(c) for c in archive.int_to_grid_index(archive.data("index"))}
        for cell in itertools.product(*map(range, dims)):
            x, y, w, h = grid.box(cell)
            assert w > 5 and h > 5
            blank = (image[int(y + h / 2), int(x + w / 2)] > 245).all()
            assert blank == (cell not in filled), (dims, cell)


def test_every_filled_cell_is_clickable_with_its_return_and_measures(page) -> None:
    [run] = [r for r in page.runs if r.included]
    data = run.archive.data(["index", "objective", "measures"])
    grid = run.archive.int_to_grid_index(data["index"])
    cells = cells_of((page.out / "report.html").read_text())
    assert len(cells) == len(data["objective"])
    by_cell = {c["data-cell"]: c for c in cells}
    for cell, value, measures in zip(grid, data["objective"], data["measures"], strict=True):
        shown = by_cell[f"({cell[0]}, {cell[1]})"]
        assert shown["data-ret"] == f"{value:,.1f}"
        assert shown["data-measures"] == ", ".join(f"{m:.2f}" for m in measures)
    with_video = [c for c in cells if "data-video" in c]
    assert len(with_video) == SMALL.count == len(page.gallery.videos[run.path])
    assert all((page.out / c["data-video"]).is_file() for c in with_video)
    assert not Path(with_video[0]["data-video"]).is_absolute()  # the folder can move


def test_the_videos_hold_the_episodes_frames_and_move(page) -> None:
    """Walker2d at 30 frames/s: the reset state, every 4th of 30 steps, and the last."""
    [videos] = page.gallery.videos.values()
    best = videos[0]
    frames = np.stack(imageio.mimread(best.path, memtest=False))
    assert best.steps == STEPS and best.frames == STEPS // 4 + 2 == len(frames)
    assert frames.shape[1:] == (64, 96, 3)
    assert len({frame.tobytes() for frame in frames}) > len(frames) // 2, "frames barely change"
    report = (page.out / "report.html").read_text()
    assert f"{SMALL.count} elites per run" in report and "Gaits" in report
    assert "](videos/" in (page.out / "report.md").read_text()  # linked from Markdown too


def test_chromium_plays_a_clicked_cells_video_without_errors(page) -> None:
    executable = find_chromium()
    if executable is None:
        pytest.skip("no Chromium to drive: install Debian's chromium (apt-get install chromium)")
    watch = (
        "(() => { const v = document.querySelector('.elite video'); return v && "
        "[v.currentTime, v.played.length ? v.played.end(0) : 0, v.videoWidth, v.error]; })()"
    )
    with Chromium(executable, width=1000, height=800) as browser:
        browser.open(page.out / "report.html")
        drawn = browser.evaluate("document.querySelectorAll('rect.cell').length")
        assert drawn == len(cells_of((page.out / "report.html").read_text())) > 0
        browser.click("rect.cell:not(.video)")
        assert "No video of this cell" in browser.evaluate("document.body.innerText")
        browser.click("rect.cell.video")
        seen: list = []
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            seen.append(browser.evaluate(watch))
            if seen[-1] and seen[-1][1] > 0.1 and len({s[0] for s in seen if s}) > 1:
                break
            time.sleep(0.2)
        panel = browser.evaluate("document.querySelector('.elite').innerText")
        errors = browser.errors()
    assert seen[-1] is not None, "no video in the panel after the click"
    assert seen[-1][3] is None and seen[-1][2] == 96, seen[-1]  # decoded, no media error
    assert seen[-1][1] > 0.1 and len({s[0] for s in seen}) > 1, f"video did not play: {seen}"
    assert "cell (" in panel and "return" in panel and "measures (" in panel
    assert f"one deterministic episode, {STEPS} steps" in panel
    assert errors == []


def test_without_opengl_the_page_says_why_and_stderr_has_one_line(
    run_dir: Path, tmp_path: Path, monkeypatch, capsys
) -> None:
    from qdil.envs import gl

    def no_gl() -> str:
        raise gl.GLUnavailableError("no headless OpenGL to render with (a test)")

    monkeypatch.setattr(gl, "use_gl_backend", no_gl)
    main(["report", str(run_dir), "--out", str(tmp_path), "--videos", "2", "--no-records"])
    err = capsys.readouterr().err
    assert err.strip().splitlines() == [
        "qdil report: no videos: no headless OpenGL to render with (a test)"
    ]
    report = (tmp_path / "report.html").read_text()
    assert "No videos: no headless OpenGL to render with (a test)." in report
    assert cells_of(report) and not (tmp_path / "videos").exists()


def test_videos_0_asks_for_none_quietly(run_dir: Path, tmp_path: Path, capsys) -> None:
    main(["report", str(run_dir), "--out", str(tmp_path), "--videos", "0", "--no-records"])
    assert capsys.readouterr().err == ""
    report = (tmp_path / "report.html").read_text()
    assert "No videos: none asked for (qdil report --videos 0)." in report
    cells = cells_of(report)
    assert cells and not any("data-video" in cell for cell in cells)
