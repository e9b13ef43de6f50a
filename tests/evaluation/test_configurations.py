"""A report's row pools one configuration: runs that differ in more than the seed are separated."""

from __future__ import annotations

import copy
from pathlib import Path

from qdil.evaluation.configurations import differing_keys, separate_configurations
from qdil.evaluation.runs import RunResult

BASE = {
    "seed": 0,
    "name": "walker_gail-seed0",
    "env": {"task": "Walker2d-v5", "num_envs": 30, "num_threads": None},
    "reward": {"class_path": "qdil.rewards.builtin.GAIL", "init_args": {"batch_size": 120}},
    "bonus": {"enabled": False, "type": "single_step", "in_fitness": True},
    "qd": {"iterations": 120, "cells": 50},
    "logging": {"progress": True, "wandb": "offline"},
    "executor": {"class_path": "qdil.rl.execution.LocalExecutor"},
}


def config(**changes: dict) -> dict:
    made = copy.deepcopy(BASE)
    for section, values in changes.items():
        made[section] = {**made[section], **values} if isinstance(values, dict) else values
    return made


def run(name: str, configuration: dict, method: str = "GAIL", labelled: bool = False) -> RunResult:
    return RunResult(
        path=Path(name),
        task="Walker2d-v5",
        method=method,
        seed=configuration["seed"],
        config=configuration,
        labelled=labelled,
    )


def test_seed_name_logging_executor_and_threads_do_not_separate() -> None:
    other = config(
        seed=1,
        name="mine",
        env={"num_threads": 2},
        logging={"progress": False, "wandb": "disabled"},
        executor={"class_path": "qdil.rl.ray.RayExecutor"},
    )
    assert differing_keys(BASE, other) == []
    runs = [run("a", config()), run("b", other)]
    separate_configurations(runs)
    assert [r.method for r in runs] == ["GAIL", "GAIL"] and not runs[0].notes


def test_a_key_an_older_config_lacks_compares_at_its_implicit_value() -> None:
    older = config()
    del older["bonus"]["in_fitness"], older["bonus"]["type"]
    assert differing_keys(older, config()) == differing_keys(config(), older) == []
    assert differing_keys(older, config(bonus={"type": "ebc"})) == ["bonus.type"]


def test_a_smoke_run_and_the_real_runs_of_one_label_get_rows_of_their_own() -> None:
    runs = [
        run("real0", config()),
        run("real1", config(seed=1)),
        run("smoke0", config(qd={"iterations": 2})),
    ]
    separate_configurations(runs)
    assert [r.method for r in runs] == [
        "GAIL [qd.iterations=120]",
        "GAIL [qd.iterations=120]",
        "GAIL [qd.iterations=2]",
    ]
    assert runs[2].notes == [
        "not pooled with the other GAIL runs: its configuration differs in qd.iterations"
    ]


def test_a_label_names_two_keys_and_counts_the_rest() -> None:
    changed = config(
        qd={"iterations": 2, "cells": 10},
        env={"num_envs": 6},
        reward={"class_path": "my.plugins.GAIL", "init_args": {"batch_size": 120}},
    )
    runs = [run("a", config()), run("b", changed)]
    separate_configurations(runs)
    assert runs[1].method == "GAIL [env.num_envs=6, qd.cells=10, +2 more]"
    assert runs[0].method == "GAIL [env.num_envs=30, qd.cells=50, +2 more]"
    assert "qd.iterations" in runs[1].notes[0] and "reward.class_path" in runs[1].notes[0]


def test_a_new_seed_joins_the_label_its_configuration_has_in_the_records() -> None:
    kept = [run(f"kept{s}", config(seed=s), method="WQDIL latent 8", labelled=True) for s in (0, 1)]
    new = run("walker_gail-seed2", config(seed=2))
    other = run("walker_gail_smoke", config(qd={"iterations": 2}))
    separate_configurations([*kept, new, other])
    assert new.method == "WQDIL latent 8" and "as the runs of its configuration" in new.notes[0]
    assert other.method == "GAIL"  # no labelled run of its configuration: its own label


def test_left_out_runs_are_not_touched() -> None:
    broken = run("broken", config(qd={"iterations": 2}))
    broken.problems.append("no metrics.csv")
    runs = [run("a", config()), broken]
    separate_configurations(runs)
    assert [r.method for r in runs] == ["GAIL", "GAIL"]
