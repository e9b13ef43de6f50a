"""Stage the packages the GPU machine lacks, across calls of a warm machine.

A call of the GPU machine carries the working tree and what ``carry`` names in 64 MiB;
qdil's GPU needs (warp-lang alone is a 149 MB wheel) do not fit one call. Here::

    python tools/device_stage.py                # wheels -> one tar.xz -> parts in .stage/

downloads, for the machine's Python (3.12, manylinux x86_64), every distribution qdil's GPU
check needs that the machine's image lacks (``tools/device_packages.txt``), at the versions
installed here; unpacks them as ``pip install --target`` would; packs the result as one
xz-compressed tar and splits it into parts that each fit one call beside the tracked tree.
It prints one command per call. On the machine, ``bash tools/device_receive.sh`` keeps each
call's part in ``/tmp`` and, once every part is there and its checksum holds, unpacks them
into ``/tmp/site``: ``PYTHONPATH=/tmp/site:src`` then runs qdil. The calls must follow one
another while the machine stays warm (docs/guides/gpu.md#on-a-borrowed-gpu).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
from importlib.metadata import PackageNotFoundError, distribution
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]
CALL = 64 * 2**20  # bytes a call carries: the tree, the parts
MARGIN = 2 * 2**20  # room for files the tree gains between staging and the calls
PYTHON = "3.12"
PLATFORMS = [f"manylinux_2_{n}_x86_64" for n in (17, 24, 27, 28, 31, 34, 35)]
PLATFORMS += ["manylinux2014_x86_64", "manylinux1_x86_64"]
# what the GPU check imports: qdil with its warp extra, Ray Tune (packed trials), sybil
# (the tests' conftest); left out: W&B (the check logs with it disabled), Optuna, the video
# encoder (nothing renders)
ROOTS = ("qdil[warp,sweep]", "sybil")
LEFT_OUT = {"wandb", "optuna", "torch", "imageio-ffmpeg"}  # torch: the machine's CUDA build
# folders of the unpacked wheels that nothing the check runs reads: Ray's Java workers (a
# 33 MB jar that xz cannot shrink), Warp's own tests and examples, MuJoCo Studio's web build
TRIM = ("ray/jars", "warp/tests", "warp/examples", "mujoco_studio_wasm")


def on_device() -> set[str]:
    """The distributions the machine's image holds (``tools/device_packages.txt``)."""
    lines = (Path(__file__).with_name("device_packages.txt")).read_text().splitlines()
    return {canonicalize_name(line) for line in lines if line.strip() and not line.startswith("#")}


def needed() -> dict[str, str]:
    """Distribution -> version installed here, for everything ``ROOTS`` need on the machine.

    Requirements are followed through this environment's metadata, markers read for the
    machine (Linux, Python 3.12), stopping at what the machine has.
    """
    have, found = on_device(), {}
    todo = [Requirement(root) for root in ROOTS]
    while todo:
        requirement = todo.pop()
        name = canonicalize_name(requirement.name)
        if name != "qdil" and (name in found or name in have or name in LEFT_OUT):
            continue
        try:
            dist = distribution(requirement.name)
        except PackageNotFoundError:
            sys.exit(f"{requirement.name} is not installed here: pip install -e '.[dev,warp]'")
        if name != "qdil":  # qdil itself travels as the tree's src/
            found[name] = dist.version
        for extra in requirement.extras or {""}:
            environment = {"python_version": PYTHON, "sys_platform": "linux", "extra": extra}
            for line in dist.requires or []:
                need = Requirement(line)
                if need.marker is None or need.marker.evaluate(environment):
                    todo.append(need)
    return dict(sorted(found.items()))


def tree_size(without: tuple[str, ...] = ()) -> int:
    """Bytes of the tracked tree, links counted as links (what a call carries).

    Args:
        without: top folders of the tree the calls leave behind (see ``--without``).
    """
    names = subprocess.run(
        ["git", "ls-files", "-z"], cwd=ROOT, check=True, capture_output=True, text=True
    ).stdout.split("\0")
    names = [n for n in names if n and not any(n.startswith(f"{w}/") for w in without)]
    return sum((ROOT / n).lstat().st_size for n in names if os.path.lexists(ROOT / n))


def pip(*args: str) -> None:
    """``pip ARGS`` for the machine's Python and platform, wheels only, no dependencies."""
    target = ["--only-binary=:all:", "--python-version", PYTHON, "--implementation", "cp"]
    target += [arg for platform in PLATFORMS for arg in ("--platform", platform)]
    subprocess.run([sys.executable, "-m", "pip", *args, "--no-deps", *target], check=True)


def stage(out: Path, without: tuple[str, ...] = ()) -> dict:
    """Download, unpack, pack and split; returns the plan written to ``out/plan.json``."""
    versions = needed()
    wheels, site = out / "wheels", out / "site"
    shutil.rmtree(site, ignore_errors=True)
    pip("download", "-q", "-d", str(wheels), *[f"{n}=={v}" for n, v in versions.items()])
    pip("install", "-q", "--no-compile", "--target", str(site), *map(str, wheels.glob("*.whl")))
    for folder in TRIM:
        shutil.rmtree(site / folder, ignore_errors=True)
    tree = tree_size(without)
    plan = {"packages": versions, "without": list(without), "tree_bytes": tree}
    return pack(site, out, CALL - tree - MARGIN, plan)


def pack(site: Path, out: Path, room: int, plan: dict) -> dict:
    """``site`` as one xz-compressed tar, split into ``out/call-NN/part-NN`` of ``room`` bytes.

    Each call's folder holds its part and the plan (parts, the whole's sha256), which
    ``tools/device_receive.sh`` reads on the machine. Returns the plan.
    """
    for folder in out.glob("call-*"):
        shutil.rmtree(folder)
    packed = out / "site.tar.xz"
    with open(packed, "wb") as file:  # sorted names and no owners: the same wheels, same bytes
        tar = subprocess.Popen(
            ["tar", "-C", str(site), "--sort=name", "--owner=0", "--group=0", "-cf", "-", "."],
            stdout=subprocess.PIPE,
        )
        subprocess.run(["xz", "-T0", "-6", "-c"], stdin=tar.stdout, stdout=file, check=True)
        tar.wait()
    data = packed.read_bytes()
    packed.unlink()
    parts = [data[i : i + room] for i in range(0, len(data), room)]
    plan = plan | {
        "packed_bytes": len(data),
        "sha256": hashlib.sha256(data).hexdigest(),
        "parts": len(parts),
    }
    for k, part in enumerate(parts, 1):
        folder = out / f"call-{k:02d}"
        folder.mkdir()
        (folder / f"part-{k:02d}").write_bytes(part)
        (folder / "plan.json").write_text(json.dumps(plan, indent=1))
    (out / "plan.json").write_text(json.dumps(plan, indent=1))
    return plan


def main(argv: list[str] | None = None) -> int:
    """The command line: stage into ``--out`` and print one device call per part."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / ".stage", help="(git ignores it)")
    parser.add_argument("--list", action="store_true", help="only list what would be staged")
    parser.add_argument(
        "--without",
        nargs="*",
        default=[],
        metavar="FOLDER",
        help="top folders of the tree the calls leave behind (docs: 22 MB of records), "
        "each part then larger; before the calls, take them out of what travels: "
        "git rm -r -q --cached FOLDER && echo /FOLDER/ >> .git/info/exclude "
        "(after: git reset -q, and drop that line)",
    )
    args = parser.parse_args(argv)
    if args.list:
        for name, version in needed().items():
            print(f"{name}=={version}")
        return 0
    plan = stage(args.out, tuple(w.strip("/") for w in args.without))
    mib = 2**20
    print(
        f"{len(plan['packages'])} distributions, packed {plan['packed_bytes'] / mib:.1f} MiB; "
        f"the tree {plan['tree_bytes'] / mib:.1f} MiB: {plan['parts']} calls"
    )
    for k in range(1, plan["parts"] + 1):
        carry = args.out.resolve().relative_to(ROOT) / f"call-{k:02d}"
        print(f"call {k}: run(command='bash tools/device_receive.sh', carry=['{carry}'])")
    print("then: bash tools/device_receive.sh && PYTHONPATH=/tmp/site:src python ...")
    return 0


if __name__ == "__main__":
    sys.exit(main())
