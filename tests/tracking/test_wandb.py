"""W&B logging, offline: the run files hold the logged metrics, images and table."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SMOKE = ROOT / "recipes" / "smoke" / "walker_true.yaml"


def records(run_file: Path) -> list[bytes]:
    """Raw records of a .wandb file: a 7-byte header, then LevelDB-log 32 KiB blocks of
    chunks (crc32 u32, length u16, type u8: 1 full, 2 first, 3 middle, 4 last)."""
    data = run_file.read_bytes()
    assert data[:4] == b":W&B"
    out, pending, offset, block = [], b"", 7, 32768
    while offset + 7 <= len(data):
        left = block - offset % block
        if left < 7:  # block trailer padding
            offset += left
            continue
        length = int.from_bytes(data[offset + 4 : offset + 6], "little")
        kind = data[offset + 6]
        chunk = data[offset + 7 : offset + 7 + length]
        offset += 7 + length
        if kind == 0 and length == 0:
            continue
        pending = chunk if kind in (1, 2) else pending + chunk
        if kind in (1, 4):
            out.append(pending)
    return out


def history(run_file: Path) -> list[dict]:
    """History rows of an offline W&B run, decoded with wandb's own protobuf schema."""
    from wandb.proto import wandb_internal_pb2

    rows = []
    for data in records(run_file):
        record = wandb_internal_pb2.Record()
        record.ParseFromString(data)
        if record.WhichOneof("record_type") == "history":
            rows.append(
                {
                    item.key or "/".join(item.nested_key): json.loads(item.value_json)
                    for item in record.history.item
                }
            )
    return rows


def test_offline_wandb_run_contains_metrics_images_and_table(tmp_path: Path) -> None:
    # not silenced: the run's output is what a user sees
    env = {k: v for k, v in os.environ.items() if k != "WANDB_SILENT"} | {"WANDB_MODE": "offline"}
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "qdil.cli",
            "fit",
            str(SMOKE),
            "--name",
            "wb",
            "--logging.wandb",
            "offline",
            "--logging.heatmap_every",
            "2",
        ],
        cwd=tmp_path,
        env=env,
        check=True,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert "wandb: WARNING" not in done.stderr + done.stdout, done.stderr
    folders = list((tmp_path / "runs" / "wb" / "wandb").glob("offline-run-*"))
    assert len(folders) == 1
    run_file = next(folders[0].glob("run-*.wandb"))
    rows = history(run_file)
    # Lightning's WandbLogger keys every row on "trainer/global_step": the QD iteration
    steps = sorted(row["trainer/global_step"] for row in rows if "qd/qd_score" in row)
    assert steps == [1, 2, 3]
    metrics = {key for row in rows for key in row}
    assert {"qd/qd_score", "qd/coverage", "qd/obj_max", "perf/sps", "rl/walk_value_loss"} <= metrics
    heatmaps = [row["trainer/global_step"] for row in rows if "archive/heatmap/filenames" in row]
    assert heatmaps == [2, 3]  # every 2 iterations, and at the end
    images = list((folders[0] / "files" / "media" / "images").glob("archive/heatmap*.png"))
    assert images and all(p.stat().st_size > 1000 for p in images)
    tables = list((folders[0] / "files" / "media" / "table").rglob("*.table.json"))
    assert tables
    table = json.loads(tables[0].read_text())
    assert "objective" in table["columns"] and len(table["data"]) >= 1
    csv_rows = (tmp_path / "runs" / "wb" / "metrics.csv").read_text().strip().splitlines()
    assert len(csv_rows) == 4  # CSV logging always happens
