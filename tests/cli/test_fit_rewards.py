"""A smoke ``qdil fit`` per reward-model family, through the real command line (in-process)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest

from qdil.cli import main

ROOT = Path(__file__).resolve().parents[2]
RECIPE = ROOT / "recipes" / "smoke" / "walker_il.yaml"

FAMILIES = {
    "gail": [],
    "airl": [],
    "maxentirl": [],
    "pwil": [],
    "giril": ["--reward.pretrain_epochs", "2"],
    "wae_gail": [],
    "wae_wgail": ["--reward.reward_form", "standardized"],
    "mcwae_wgail": ["--bonus.enabled", "true", "--reward.reward_form", "calibrated"],
}
try:  # the example plugin package, installed by the README's test command
    import qdil_vail  # noqa: F401

    FAMILIES["vail"] = []
except ImportError:
    pass
try:  # the DiffAIL plugin package, installed by the README's test command
    import qdil_diffail  # noqa: F401

    # two of the 100 diffusion steps keep the reward's cost small in the smoke run
    FAMILIES["diffail"] = ["--reward.reward_timesteps", "2"]
except ImportError:
    pass


@pytest.mark.parametrize("reward", list(FAMILIES))
def test_fit_runs_each_reward_family(
    reward: str, walker_demos: Path, tmp_path: Path, monkeypatch
) -> None:
    monkeypatch.chdir(tmp_path)
    main(
        [
            "fit",
            str(RECIPE),
            "--reward",
            reward,
            *FAMILIES[reward],
            "--demos.path",
            str(walker_demos),
            "--name",
            reward,
            "--qd.iterations",
            "2",
        ]
    )
    with open(tmp_path / "runs" / reward / "metrics.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    assert [r["iteration"] for r in rows] == ["1", "2"]
    last = rows[-1]
    assert float(last["qd/num_elites"]) >= 1
    assert "qd_learned/qd_score" in last  # the learned-return archive is reported beside
    if reward not in ("pwil", "giril"):
        assert any(key.startswith("reward/") for key in last), "online models log their update"
    if reward == "mcwae_wgail":
        assert "reward/bonus_max_share" in last
        # the balance of what RL is handed: learned part + bonus part = the whole, per step
        learned, bonus = (
            float(last["reward/learned_per_step"]),
            float(last["reward/bonus_per_step"]),
        )
        assert 0.5 <= bonus < 1.0  # weight 1 × r_exp ∈ [1/2, 1)
        assert learned + bonus == pytest.approx(float(last["reward/train_per_step"]), rel=1e-4)
        anchors = float(last["reward/critic_expert"]), float(last["reward/critic_policy"])
        assert all(math.isfinite(a) for a in anchors)  # the calibration's μ_e and μ_π
    else:
        assert last["reward/learned_per_step"] == last["reward/train_per_step"]
    if reward == "wae_wgail":  # standardized: the policy's spread is measured and logged
        assert float(last["reward/critic_policy_std"]) > 0


def metrics_of(run_dir: Path) -> list[dict[str, str]]:
    with open(run_dir / "metrics.csv", newline="") as file:
        return list(csv.DictReader(file))


def test_fit_with_the_ebc_bonus_resumes_with_the_checkpoints_archive(
    walker_demos: Path, tmp_path: Path, monkeypatch
) -> None:
    """EBC through the real command line; a resumed run continues exactly.

    The bonus reads the CMA-MAE archive, which a resume restores from the checkpoint. On a
    2×2 grid most rollout windows of iteration 2 fall in cells iteration 1 filled, so a
    bonus still reading the empty archive of the rebuilt run would pay every window.
    """
    monkeypatch.chdir(tmp_path)
    args = [
        "fit",
        str(RECIPE),
        *("--demos.path", str(walker_demos)),
        *("--bonus.enabled", "true", "--bonus.type", "ebc", "--bonus.weight", "2"),
        *("--qd.cells", "2", "--logging.checkpoint_every", "1"),
    ]
    main([*args, "--name", "whole", "--qd.iterations", "2"])
    main([*args, "--name", "split", "--qd.iterations", "1"])
    main(["fit", "--resume", "runs/split", "--qd.iterations", "2"])
    whole, split = metrics_of(tmp_path / "runs" / "whole"), metrics_of(tmp_path / "runs" / "split")
    assert [r["iteration"] for r in split] == ["1", "2"]
    for key in whole[-1]:
        if not key.startswith("perf/"):
            assert split[-1][key] == whole[-1][key], key
    last = whole[-1]
    share = float(last["reward/bonus_novel_share"])
    assert 0.0 <= share < 1.0
    learned, bonus = float(last["reward/learned_per_step"]), float(last["reward/bonus_per_step"])
    assert bonus == pytest.approx(2.0 * share, rel=1e-6)  # valid steps: whole windows
    assert learned + bonus == pytest.approx(float(last["reward/train_per_step"]), rel=1e-4)


def test_imitation_without_demos_is_refused(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(
        SystemExit, match=r"demos\.path: the gail reward model needs demonstrations"
    ):
        main(["fit", str(RECIPE), "--name", "x"])


def test_demos_of_another_task_are_refused(walker_demos: Path, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(
        SystemExit, match="recorded on 'Walker2d-v5', but the run's task is 'Hopper-v5'"
    ):
        main(
            [
                "fit",
                str(RECIPE),
                "--env.task",
                "Hopper-v5",
                "--demos.path",
                str(walker_demos),
                "--name",
                "y",
            ]
        )


def test_a_missing_demo_file_says_how_to_make_one_and_leaves_no_run(
    tmp_path: Path, monkeypatch
) -> None:
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit, match=r"humanoid\.npz: no such file .*qdil demos RUN_DIR"):
        main(["fit", str(RECIPE), "--demos.path", "humanoid.npz", "--name", "z"])
    assert not (tmp_path / "runs" / "z").exists()


@pytest.mark.parametrize(
    ("reward", "options", "absorbing"),
    [
        ("gail", ["--reward.reward_form", "raw"], "learned"),
        (
            "mcwae_wgail",
            ["--bonus.enabled", "true", "--reward.reward_form", "standardized_logit"],
            "floor",
        ),
    ],
)
def test_fit_with_absorbing_states_logs_what_a_fall_is_worth(
    reward: str,
    options: list[str],
    absorbing: str,
    walker_demos: Path,
    tmp_path: Path,
    monkeypatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    main(
        [
            "fit", str(RECIPE), "--reward", reward, *options, "--reward.absorbing", absorbing,
            "--demos.path", str(walker_demos), "--name", reward, "--qd.iterations", "2",
        ]
    )  # fmt: skip
    with open(tmp_path / "runs" / reward / "metrics.csv", newline="") as file:
        rows = list(csv.DictReader(file))
    assert [r["iteration"] for r in rows] == ["1", "2"]
    for row in rows:  # the smoke walker falls within its 50-step episodes
        assert float(row["survival/falls_per_1k_steps"]) > 0
        assert math.isfinite(float(row["reward/absorbing"]))
    if absorbing == "floor":  # iteration 1 runs before any update: the floor is 0 then
        assert float(rows[0]["reward/absorbing"]) == 0.0
        assert float(rows[1]["reward/absorbing"]) < 0.0  # the lowest policy reward, signed
