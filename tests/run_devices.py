"""Test helpers: build a run from a recipe in-process, and find tensors off its device."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import fields
from pathlib import Path

import torch

from qdil.cli.fit import build as build_parsed
from qdil.cli.fit import fit_parser, parse_fit
from qdil.qd.state import Run
from qdil.rl.normalize import RunningMeanStd


def build(recipe: Path, run_dir: Path, *overrides: str) -> Run:
    """The run ``qdil fit recipe overrides...`` would start, built but not looped."""
    config, _, _ = parse_fit([str(recipe), *overrides])
    config.name = "devices"
    init = fit_parser().instantiate(config)
    return build_parsed(init, "devices", run_dir, "", resume=False)


def _tensors(name: str, value: object) -> Iterator[tuple[str, torch.Tensor]]:
    if isinstance(value, torch.Tensor):
        yield name, value
    elif isinstance(value, torch.nn.Module):
        for key, tensor in [*value.named_parameters(), *value.named_buffers()]:
            yield f"{name}.{key}", tensor
    elif isinstance(value, torch.optim.Optimizer):
        for i, state in enumerate(value.state.values()):
            for key, tensor in state.items():
                if key != "step":  # Adam keeps its step count on the CPU on purpose
                    yield from _tensors(f"{name}.state{i}.{key}", tensor)
    elif isinstance(value, RunningMeanStd):
        yield from ((f"{name}.{key}", t) for key, t in (("mean", value.mean), ("var", value.var)))
        yield f"{name}.count", value.count
    elif isinstance(value, dict):
        for key, item in value.items():
            yield from _tensors(f"{name}.{key}", item)


def run_tensors(run: Run) -> dict[str, torch.Tensor]:
    """Every tensor of a run's torch side: VPPO, the scorer, the collector, reward model,
    bonus, demos."""
    vppo = run.estimator
    parts = {
        "jacobian_critic": vppo.jacobian_critic,
        "walk_critic": vppo.walk_critic,
        "jacobian_critic_opt": vppo.jacobian_critic_opt,
        "walk_critic_opt": vppo.walk_critic_opt,
        "jacobian_returns": vppo.jacobian_returns,
        "walk_returns": vppo.walk_returns,
        "action_map": vars(run.scorer.action_map),
        "collector_action_map": vars(run.executor.collector.action_map),
        "reward": run.reward,
        "expert": {}
        if run.expert is None
        else {f.name: getattr(run.expert, f.name) for f in fields(run.expert)},
    }
    found = {name: t for key, value in parts.items() for name, t in _tensors(key, value)}
    found["generator"] = torch.empty(0, device=run.noise.device)
    return found


def off_device(run: Run, device: torch.device) -> list[str]:
    """Names of the run's tensors that are not on ``device``."""
    return [
        f"{name} on {t.device}"
        for name, t in run_tensors(run).items()
        if t.device.type != device.type
    ]
