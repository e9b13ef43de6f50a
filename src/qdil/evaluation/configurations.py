"""Which runs a report pools: one row per method label and effective configuration.

:func:`separate_configurations` gives runs of one label that differ in a compared recipe key
(any but :data:`NOT_COMPARED`) rows of their own, and lets a run with the default label join
the label of its configuration's labelled runs. Why: docs/guides/reproduce-paper-results.md.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any, Protocol

from qdil.qd.checkpoint import config_differences

if TYPE_CHECKING:
    from qdil.evaluation.runs import Groups

NOT_COMPARED = ("seed", "name", "logging", "executor", "env.num_threads")
"""Recipe keys (and sections) whose values never separate runs."""

SHOWN_KEYS = 2
"""Differing keys named in a separated row's label; the run's note names them all."""


class Configured(Protocol):
    """What this module reads and sets of a run (:class:`qdil.evaluation.runs.RunResult`)."""

    task: str | None
    method: str | None
    config: dict[str, Any]
    labelled: bool
    notes: list[str]
    included: bool


def differing_keys(a: Mapping[str, Any], b: Mapping[str, Any]) -> list[str]:
    """The compared recipe keys whose values differ between two resolved recipes, sorted."""

    def keys(old: Mapping[str, Any], new: Mapping[str, Any]) -> set[str]:
        return {line.split(": ", 1)[0] for line in config_differences(old, new, NOT_COMPARED)}

    # both ways: an older config's missing key counts as its implicit value on either side
    return sorted(keys(a, b) & keys(b, a))


def _value(config: Mapping[str, Any], key: str) -> Any:
    node: Any = config
    for part in key.split("."):
        if not isinstance(node, Mapping) or part not in node:
            return "(absent)"
        node = node[part]
    return node


def _short(value: Any) -> str:
    """A value as a label shows it: a class path by its class name, at most 24 characters."""
    text = value if isinstance(value, str) else json.dumps(value)
    if isinstance(value, str) and all(part.isidentifier() for part in value.split(".")):
        text = value.rpartition(".")[2]
    return text if len(text) <= 24 else text[:23] + "…"


def _partition(runs: list[Configured]) -> list[list[Configured]]:
    """Runs in groups whose members agree with each other on every compared key."""
    parts: list[list[Configured]] = []
    for run in runs:
        for part in parts:
            if all(not differing_keys(run.config, other.config) for other in part):
                part.append(run)
                break
        else:
            parts.append([run])
    return parts


def _join_labels(runs: list[Configured]) -> None:
    """Give a run with the default label the label its configuration has among labelled runs."""
    labelled = [run for run in runs if run.labelled]
    for run in runs:
        if run.labelled:
            continue
        labels = {
            other.method
            for other in labelled
            if other.task_label == run.task_label and not differing_keys(run.config, other.config)
        }
        if len(labels) == 1 and run.method not in labels:
            (label,) = labels
            run.notes.append(f"labelled {label}, as the runs of its configuration ({run.method})")
            run.method = label


def separate_configurations(runs: Iterable[Configured]) -> None:
    """Relabel included runs so that each label of a task holds one configuration.

    Args:
        runs: the report's runs; left-out ones are not touched.
    """
    included = [run for run in runs if run.included]
    _join_labels(included)
    groups: dict[tuple[str | None, str | None], list[Configured]] = {}
    for run in included:
        groups.setdefault((run.task_label, run.method), []).append(run)
    for (_, method), members in groups.items():
        parts = _partition(members)
        if len(parts) < 2:
            continue
        taken: set[str] = set()
        for part in parts:
            config = part[0].config
            others = [other[0].config for other in parts if other is not part]
            keys = sorted({key for other in others for key in differing_keys(config, other)})
            shown = ", ".join(f"{key}={_short(_value(config, key))}" for key in keys[:SHOWN_KEYS])
            more = f", +{len(keys) - SHOWN_KEYS} more" if len(keys) > SHOWN_KEYS else ""
            label, n = f"{method} [{shown}{more}]", 1
            while label in taken:  # two configurations alike in the keys shown
                n += 1
                label = f"{method} [{shown}{more}] #{n}"
            taken.add(label)
            for run in part:
                run.method = label
                run.notes.append(
                    f"not pooled with the other {method} runs: its configuration differs in "
                    + ", ".join(keys)
                )


def flag_duplicate_seeds(groups: Groups) -> None:
    """Add a note to every run that shares its seed with another run of its task and method."""
    for task, runs_by_method in groups.items():
        for method, runs in runs_by_method.items():
            for run in runs:
                twins = [str(r.path) for r in runs if r is not run and r.seed == run.seed]
                if twins:
                    run.notes.append(
                        f"seed {run.seed} also used by {', '.join(twins)} ({task} / {method})"
                    )
