"""The default name of a new run: the recipe's, or one that says what the command line ran.

Only the standard library at import time: the commands that name runs stay light.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from jsonargparse import Namespace


def _reward_class(class_path: str) -> type | None:
    """The class at ``class_path`` (``module.Class``), or None if it does not import."""
    module, _, name = class_path.rpartition(".")
    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError, ValueError):
        return None


BONUS_TAGS = ("bonus", "ebc")
"""Name parts of an enabled bonus, by ``bonus.type`` (``single_step``, ``ebc``), as the
shipped recipes spell them (``walker_mcwae_gail_bonus``, ``walker_gail_ebc``)."""


def _bonus_tag(bonus: Any) -> str:
    """``bonus``, ``ebc`` or ``""`` (disabled) for a bonus section (a mapping or namespace)."""
    if not bonus.get("enabled", False):  # BonusConfig's defaults
        return ""
    return "ebc" if bonus.get("type", "single_step") == "ebc" else "bonus"


def run_stem(stem: str, recipe: dict, config: Namespace) -> str:
    """The stem of a new run's default name (``<stem>-seed<seed>``): what ran, in words.

    The method's stem (:func:`method_stem`), then, when ``env.integrator`` replaces the
    task model's own, ``_`` and its name: ``walker_ppga.yaml --env.integrator euler`` gives
    ``walker_ppga_euler`` (a stem that already ends with it keeps it).
    """
    stem = method_stem(stem, recipe, config)
    integrator = getattr(config.env, "integrator", None)
    if integrator is None or stem.endswith(f"_{integrator}"):
        return stem
    from qdil.envs.tasks import changed_for_task  # imports MuJoCo: only when asked

    try:
        changed = changed_for_task(config.env.task, config.env.task_kwargs, integrator)
    except (ValueError, FileNotFoundError):  # the run's own check names the bad task
        return stem
    return f"{stem}_{changed}" if changed else stem


def method_stem(stem: str, recipe: dict, config: Namespace) -> str:
    """The stem of what ran: the recipe's, or the method the command line changed it to.

    The recipe file's stem, unless the command line changed the method. When it replaced
    the recipe's reward model (``--reward gail``), the stem's first ``_``-separated part,
    the registered name of the model that runs and, if a bonus is on, ``_bonus`` or
    ``_ebc``: ``walker_mcwae.yaml --reward gail --bonus.enabled false`` gives
    ``walker_gail``, without ``--bonus.enabled false`` ``walker_gail_bonus`` (a class
    without a registered name: its name in lower case). When only the bonus was switched
    (on, off, or to the other type), the stem without its bonus part, then the bonus that
    runs: ``walker_gail.yaml --bonus.enabled true --bonus.type ebc`` gives
    ``walker_gail_ebc``, ``walker_gail_ebc.yaml --bonus.enabled false`` ``walker_gail``,
    and ``walker_mcwae.yaml --bonus.enabled false``, whose stem names no bonus,
    ``walker_mcwae_nobonus``. A recipe run as it is, or with other options, keeps its stem.

    Args:
        stem: the recipe file's stem.
        recipe: the recipe file's content, reward names resolved to class paths.
        config: the parsed configuration, command-line overrides applied.
    """
    tag = _bonus_tag(config.bonus)
    reward = recipe.get("reward")
    written = reward.get("class_path") if isinstance(reward, dict) else reward
    running = getattr(config.reward, "class_path", None)
    cls = _reward_class(running) if isinstance(running, str) and running != written else None
    if cls is not None and isinstance(written, str) and cls is not _reward_class(written):
        name = getattr(cls, "name", "") or cls.__name__.lower()
        return f"{stem.split('_', 1)[0]}_{name}" + (f"_{tag}" if tag else "")
    if tag == _bonus_tag(recipe.get("bonus") or {}):
        return stem
    base, _, last = stem.rpartition("_")
    if base and last in BONUS_TAGS:  # the stem names the recipe's bonus: replace it
        return f"{base}_{tag}" if tag else base
    return f"{stem}_{tag or 'nobonus'}"
