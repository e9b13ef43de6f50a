"""Keep one copy of each file under a folder: later copies become relative symbolic links.

A run recorded in several reports (a comparison, then a summary over comparisons) is the
same bytes in each; the repository keeps them once, so that its tracked tree travels in one
call of a GPU machine with room for wheels (docs/guides/gpu.md#on-a-borrowed-gpu)::

    python tools/link_duplicates.py docs/reports           # link, and say what it saved
    python tools/link_duplicates.py docs/reports --check   # exit 1 if any copy is left

The copy that stays is the one git added first (untracked files lose to tracked ones; ties
go to the shorter, then the alphabetically first path). Readers open a link as the file.
An image is not linked: the pages of its report (``*.md``, ``*.html`` in the folder below
``root`` that holds it) are rewritten to show the kept copy, and the image goes, since a
web viewer may not follow a link to an image.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import re
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

SMALLEST = 1024  # bytes: smaller copies cost less than the link's clarity
IMAGES = {".png", ".svg", ".gif", ".jpg", ".jpeg"}


def duplicates(root: Path) -> list[list[Path]]:
    """Groups of two or more regular files under ``root`` with the same bytes."""
    by_digest: dict[str, list[Path]] = defaultdict(list)
    for path in sorted(root.rglob("*")):
        if path.is_symlink() or not path.is_file() or path.stat().st_size < SMALLEST:
            continue
        by_digest[hashlib.sha256(path.read_bytes()).hexdigest()].append(path)
    return [paths for paths in by_digest.values() if len(paths) > 1]


def added_at(paths: list[Path]) -> dict[Path, float]:
    """The time git first added each path (infinity where git does not track it)."""
    times = {path: float("inf") for path in paths}
    for path in paths:
        out = subprocess.run(
            ["git", "log", "--diff-filter=A", "--follow", "--format=%ct", "--", path.name],
            cwd=path.parent,
            capture_output=True,
            text=True,
        ).stdout.split()
        if out:
            times[path] = float(out[-1])
    return times


def link(group: list[Path], root: Path) -> tuple[Path, int]:
    """Replace all but the first-added file of ``group`` by links to it (images: see above).

    Returns:
        the file kept and the bytes the links saved.
    """
    times = added_at(group)
    keep = min(group, key=lambda p: (times[p], len(str(p)), str(p)))
    saved = 0
    for path in group:
        if path == keep:
            continue
        saved += path.stat().st_size
        if path.suffix.lower() in IMAGES:
            show_instead(path, keep, pages_of(path, root))
            path.unlink()
            continue
        tmp = path.with_name(path.name + ".link-tmp")
        tmp.unlink(missing_ok=True)
        tmp.symlink_to(os.path.relpath(keep, path.parent))
        tmp.replace(path)  # atomic: the path is never missing
    return keep, saved


def pages_of(path: Path, root: Path) -> list[Path]:
    """The pages of the report that holds ``path``: its folder just below ``root``."""
    report = path.parent
    while report.parent != root and report.parent != report:
        report = report.parent
    return sorted(p for p in report.rglob("*") if p.suffix in (".md", ".html") and p.is_file())


def show_instead(path: Path, keep: Path, pages: list[Path]) -> None:
    """Rewrite each page's reference to ``path`` (in ``src="..."`` or ``](...)``) as ``keep``."""
    for page in pages:
        old = os.path.relpath(path, page.parent)
        new = os.path.relpath(keep, page.parent)
        text = page.read_text()
        changed = re.sub(rf'(?<=["(]){re.escape(old)}(?=[")])', new, text)
        if changed != text:
            page.write_text(changed)


def image_links(root: Path) -> int:
    """Replace image links under ``root`` (from before images were not linked); count them."""
    count = 0
    for path in sorted(root.rglob("*")):
        if path.is_symlink() and path.suffix.lower() in IMAGES:
            show_instead(path, path.resolve(), pages_of(path, root))
            path.unlink()
            count += 1
    return count


def main(argv: list[str] | None = None) -> int:
    """The command line: link the copies under a folder, or only check for them."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("root", type=Path, help="the folder whose copies become links")
    parser.add_argument(
        "--check", action="store_true", help="only say whether copies are left (exit 1 if so)"
    )
    args = parser.parse_args(argv)
    if not args.root.is_dir():
        parser.error(f"{args.root} is not a folder")
    if not args.check and (count := image_links(args.root)):
        print(f"{count} linked images now shown from the kept copy")
    groups = duplicates(args.root)
    extra = sum(path.stat().st_size for group in groups for path in group[1:])
    if args.check:
        for group in groups:
            print(f"same bytes: {', '.join(str(p) for p in group)}")
        print(f"{len(groups)} files held more than once under {args.root} ({extra:,} bytes)")
        return 1 if groups else 0
    saved = sum(link(group, args.root)[1] for group in groups)
    print(f"{len(groups)} files held more than once: {saved:,} bytes now links")
    return 0


if __name__ == "__main__":
    sys.exit(main())
