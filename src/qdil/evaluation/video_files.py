"""Video files: where :func:`~qdil.evaluation.video.render_elites` writes, and how.

MP4 is H.264 in yuv420p, which browsers play (Debian's Chromium among them, which the
report page's test drives); GIF frames are quantised to 256 colours as they come.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

FORMATS = ("mp4", "gif")
"""Video formats, by file suffix."""


class VideoWriter:
    """Writes frames to an MP4 (ffmpeg, streamed) or a GIF (Pillow, on :meth:`close`).

    Args:
        path: the file; its suffix picks the format.
        fps: frames per second.
    """

    def __init__(self, path: Path, fps: float) -> None:
        self.path, self.fps = path, fps
        self.count = 0
        self._gif: list[Image.Image] = []
        self._mp4: Any = None
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.suffix.lower() == ".mp4":
            import imageio.v2 as imageio

            self._mp4 = imageio.get_writer(
                path, format="FFMPEG", mode="I", fps=fps, codec="libx264", macro_block_size=2
            )

    def append(self, frame: np.ndarray) -> None:
        """Add an (H, W, 3) uint8 frame."""
        self.count += 1
        if self._mp4 is not None:
            self._mp4.append_data(frame)
        else:  # 256 colours now: a GIF's frames are kept until the end
            self._gif.append(Image.fromarray(frame).quantize(method=Image.Quantize.FASTOCTREE))

    def close(self) -> None:
        """Finish the file."""
        if self._mp4 is not None:
            self._mp4.close()
        elif self._gif:
            self._gif[0].save(
                self.path,
                save_all=True,
                append_images=self._gif[1:],
                duration=round(1000 / self.fps),
                loop=0,
            )


def video_paths(out: Path, cells: list[tuple[int, ...]], which: str, fmt: str) -> list[Path]:
    """Where the videos of ``cells`` go: ``out`` itself, or ``out/{which}_cell_I_J.{fmt}``.

    Raises:
        ValueError: for an unknown suffix, or a file given for several videos.
    """
    if out.suffix:
        if out.suffix.lower() not in (f".{name}" for name in FORMATS):
            raise ValueError(
                f"--out {out}: unknown video suffix {out.suffix!r}; give a .mp4 or .gif file, "
                "or a folder"
            )
        if len(cells) > 1:
            raise ValueError(f"--out {out}: {len(cells)} videos need a folder, not a file")
        return [out]
    return [out / f"{which}_cell_{'_'.join(map(str, cell))}.{fmt}" for cell in cells]
