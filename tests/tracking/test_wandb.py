"""W&B logging: offline run files hold the metrics, images and table; a resume continues the
W&B run; a finished run resumed writes nothing; online without a login stops before any work."""

from __future__ import annotations

import json
import os
from pathlib import Path

from tests.commands import SMOKE, qdil


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


def run_record(run_file: Path):
    """The run record (id, resume setting) of an offline W&B run."""
    from wandb.proto import wandb_internal_pb2

    for data in records(run_file):
        record = wandb_internal_pb2.Record()
        record.ParseFromString(data)
        if record.WhichOneof("record_type") == "run":
            return record.run
    raise AssertionError(f"no run record in {run_file}")


def files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_offline_wandb_run_holds_the_metrics_and_a_resume_continues_it(tmp_path: Path) -> None:
    # not silenced: the run's output is what a user sees
    env = {k: v for k, v in os.environ.items() if k != "WANDB_SILENT"} | {"WANDB_MODE": "offline"}
    args = ["--logging.wandb", "offline", "--logging.heatmap_every", "2"]
    args += ["--logging.wandb_group", "sweep-1"]
    done = qdil("fit", str(SMOKE), "--name", "wb", *args, cwd=tmp_path, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
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
    # the elites' gaits: 4 videos of the deployable archive at the last step, where GL renders
    from qdil.envs.gl import GLUnavailableError, use_gl_backend

    try:
        use_gl_backend()
    except GLUnavailableError:
        assert "W&B videos skipped" in done.stderr, done.stderr[-3000:]
    else:
        videos = list((folders[0] / "files" / "media" / "videos").rglob("*.mp4"))
        assert len(videos) == 4 and all(p.stat().st_size > 1000 for p in videos), videos
        logged = [row for row in rows if "archive/videos/count" in row]
        assert [(row["trainer/global_step"], row["archive/videos/count"]) for row in logged] == [
            (3, 4)
        ]
        assert len(list((tmp_path / "runs" / "wb" / "videos" / "wandb").glob("*.mp4"))) == 4
    csv_rows = (tmp_path / "runs" / "wb" / "metrics.csv").read_text().strip().splitlines()
    assert len(csv_rows) == 4  # CSV logging always happens

    # a resume continues the same W&B run: offline, wandb writes each start into a folder
    # of its own, with the run's id, and `wandb sync` uploads them in order as one run
    run_dir = tmp_path / "runs" / "wb"
    run_id = (run_dir / "wandb" / "qdil-run-id").read_text().strip()
    assert run_id.startswith("wb-") and run_record(run_file).run_id == run_id
    assert run_record(run_file).run_group == "sweep-1"  # qdil sweep groups its runs
    more = qdil("fit", "--resume", "runs/wb", "--qd.iterations", "4", cwd=tmp_path, env=env)
    assert more.returncode == 0, more.stderr[-3000:]
    assert "wandb: WARNING" not in more.stderr + more.stdout, more.stderr
    second = set(run_dir.glob("wandb/offline-run-*")) - set(folders)
    assert len(second) == 1
    resumed = next(second.pop().glob("run-*.wandb"))
    assert run_record(resumed).run_id == run_id and run_record(resumed).resume
    steps = sorted({row["trainer/global_step"] for row in history(resumed) if "qd/qd_score" in row})
    assert steps == [4]

    # a finished run resumed: one line, and not a byte written (no W&B run either)
    before = files(run_dir)
    again = qdil("fit", "--resume", "runs/wb", cwd=tmp_path, env=env)
    assert again.returncode == 0, again.stderr[-3000:]
    assert again.stderr.strip().splitlines() == [
        "runs/wb is finished: iteration 4 of 4; nothing to do (--qd.iterations N continues it to N)"
    ]
    assert files(run_dir) == before


def logged_out(home: Path) -> dict[str, str]:
    """The environment of a user who never ran `wandb login`: no key, no .netrc, no settings."""
    import matplotlib

    env = {k: v for k, v in os.environ.items() if not k.startswith("WANDB_")}
    env |= {"HOME": str(home), "NETRC": str(home / "no-netrc"), "XDG_CONFIG_HOME": str(home)}
    # matplotlib's font cache, so that a fresh home does not rebuild it (and say so)
    return env | {"MPLCONFIGDIR": matplotlib.get_cachedir()}


def test_online_without_a_login_stops_before_any_work_in_one_line(tmp_path: Path) -> None:
    work = tmp_path / "work"
    work.mkdir()
    done = qdil("fit", str(SMOKE), "--logging.wandb", "online", cwd=work, env=logged_out(tmp_path))
    assert done.returncode != 0
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith("qdil fit: error: --logging.wandb online needs a W&B login")
    assert "wandb login" in lines[0] and "--logging.wandb offline" in lines[0]
    assert list(work.iterdir()) == []  # no run directory, nothing else


def test_a_run_keeps_its_wandb_id(tmp_path: Path) -> None:
    from qdil.tracking import WANDB_ID, wandb_run_id

    first = wandb_run_id(tmp_path / "a", "walker_mcwae-seed0")
    assert first.startswith("walker_mcwae-seed0-") and first != "walker_mcwae-seed0"
    assert wandb_run_id(tmp_path / "a", "walker_mcwae-seed0") == first  # every resume
    assert wandb_run_id(tmp_path / "b", "walker_mcwae-seed0") != first  # same name, new run
    # a run started before ids were kept: wandb/ exists, and its id was its name
    (tmp_path / "old" / "wandb").mkdir(parents=True)
    assert wandb_run_id(tmp_path / "old", "x/y") == "x-y"
    assert (tmp_path / "old" / WANDB_ID).read_text().strip() == "x-y"
