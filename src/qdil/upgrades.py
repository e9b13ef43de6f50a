"""Recipes of older runs, read as today's: classes, keys and values that moved.

A run directory keeps its resolved recipe (``config.yaml``, and a copy in every checkpoint);
one written before a class or key moved still resumes, re-scores and reports, because every
reader of a stored recipe passes it through :func:`upgraded` first.
"""

from __future__ import annotations

from typing import Any

MOVED_CLASSES = {
    "qdil.rl.execution.LocalExecutor": "qdil.executors.LocalExecutor",
    "qdil.rl.VPPO": "qdil.qd.VPPO",
    "qdil.rl.vppo.VPPO": "qdil.qd.VPPO",
}
"""Class paths that the recipes of older runs store, and where those classes are now."""

MOVED_KEYS = {
    ("rl", "init_args", "actor_hidden"): ("policy", "hidden"),
    ("rl", "init_args", "obs_clip"): ("policy", "obs_clip"),
}
"""Keys that older recipes hold, and where they are now (the policy family left VPPO)."""

MOVED_VALUES = {
    ("reward", "init_args", "absorbing"): {True: "learned", False: None},
}
"""Values that older recipes hold, and what they are now (``absorbing: true`` was DAC's
learned absorbing state before ``floor`` joined it)."""

RENAMED_FORMS = {"gail": "log1-d", "critic": "raw", "logit": "raw", "f": "raw"}
"""``reward_type`` values of older recipes and the ``reward_form`` that is the same transform
(each model had its own names for one form). AIRL's ``logit`` became ``score_type: logit``."""


def _reward_form(content: dict[str, Any]) -> None:
    """Move an older recipe's ``reward.init_args.reward_type`` to ``reward_form``, in place."""
    reward = content.get("reward")
    args = reward.get("init_args") if isinstance(reward, dict) else None
    if not isinstance(args, dict) or "reward_type" not in args:
        return
    old = args.pop("reward_type")
    model = str(reward.get("class_path", "")).rpartition(".")[2].lower()
    if model == "airl" and old == "logit":
        args.setdefault("score_type", "logit")
    args.setdefault("reward_form", RENAMED_FORMS.get(old, old))


def _classes(value: Any) -> Any:
    if isinstance(value, dict):
        return {key: _classes(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_classes(item) for item in value]
    return MOVED_CLASSES.get(value, value) if isinstance(value, str) else value


def upgraded(content: dict[str, Any]) -> dict[str, Any]:
    """A recipe's content with moved class paths and keys where they are now.

    Args:
        content: a recipe or a stored resolved recipe (nested dicts, as YAML reads it).

    Returns:
        A new dict; ``content`` is left as it was. A moved key's value goes to its new
        place unless the recipe sets that place itself.
    """
    content = _classes(content)
    for old, new in MOVED_KEYS.items():
        parent = content
        for part in old[:-1]:
            parent = parent.get(part) if isinstance(parent, dict) else None
        if not isinstance(parent, dict) or old[-1] not in parent:
            continue
        value = parent.pop(old[-1])
        target = content
        for part in new[:-1]:
            if not isinstance(target.get(part), dict):
                target[part] = {}
            target = target[part]
        target.setdefault(new[-1], value)
    for key, values in MOVED_VALUES.items():
        parent = content
        for part in key[:-1]:
            parent = parent.get(part) if isinstance(parent, dict) else None
        value = parent.get(key[-1]) if isinstance(parent, dict) else None
        if isinstance(value, bool) and value in values:  # True and 1 differ here
            parent[key[-1]] = values[value]
    _reward_form(content)
    return content


def policy_settings(content: dict[str, Any]) -> tuple[tuple[int, ...], float]:
    """(hidden widths, observation clip) of the policies of a stored recipe, new or old."""
    policy = upgraded(content).get("policy") or {}
    return tuple(policy.get("hidden", (128, 128))), float(policy.get("obs_clip", 10.0))
