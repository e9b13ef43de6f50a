"""``MetricsFollower``: the rows a running trial appends to its ``metrics.csv``, once each.

Each look reads only what was appended since the last one (the file's bytes from where the
last look stopped, up to its last complete line), so following a run costs its new rows,
not its history. A rewritten file (the tracker widens the header when new metrics appear,
and a resumed run truncates rows logged after its checkpoint) is read again from the top,
and rows already reported, by iteration, are not reported again.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path


class MetricsFollower:
    """New rows of a ``metrics.csv``, by iteration.

    Args:
        path: the file (it may not exist yet).
        after: report only rows of later iterations.
    """

    def __init__(self, path: Path, after: int = 0) -> None:
        self.path, self.after = path, after
        self._file: tuple[int, int] | None = None  # (device, inode) of the file being read
        self._offset = 0
        self._header: list[str] | None = None

    def rows(self) -> list[dict[str, str]]:
        """The complete rows appended since the last call whose iteration is new, in order."""
        try:
            status = os.stat(self.path)
        except FileNotFoundError:
            return []
        identity = (status.st_dev, status.st_ino)
        if identity != self._file or status.st_size < self._offset:  # replaced, or cut
            self._file, self._offset, self._header = identity, 0, None
        with open(self.path, "rb") as file:
            file.seek(self._offset)
            chunk = file.read()
        complete = chunk[: chunk.rfind(b"\n") + 1]  # a row being written waits for its end
        self._offset += len(complete)
        lines = complete.decode().splitlines()
        if self._header is None and lines:
            self._header, lines = next(csv.reader(lines[:1])), lines[1:]
        found = []
        for values in csv.reader(lines):
            row = dict(zip(self._header or [], values, strict=False))
            if int(float(row["iteration"])) > self.after:
                found.append(row)
                self.after = int(float(row["iteration"]))
        return found


def last_iteration(path: Path) -> int:
    """The iteration of the last row of a ``metrics.csv`` (0 for none, or no file)."""
    rows = MetricsFollower(path).rows()
    return int(float(rows[-1]["iteration"])) if rows else 0
