"""Reward models by name: registry names read from source, and names in recipes.

:func:`declared_name` reads a class's registry name from its source, without importing it.
:func:`resolve_reward_names` and :func:`rewrite_reward_flag` turn ``reward: gail`` and
``--reward GAIL`` into class paths before a recipe is parsed.

Reading records (``qdil report``) needs each run's reward name, not its model: importing a
reward model imports Lightning and torch (seconds). :func:`declared_name` finds the
``@register_reward("name")`` decorator of the class in its module's source, the one place
the name is declared; ``None`` where the source does not say (the caller then imports).
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path
from typing import Any

from qdil.rewards.source import is_register_call, module_source


def declared_name(class_path: str) -> str | None:
    """The name ``@register_reward`` gives the class at ``class_path``, read from its source.

    A class a package re-exports (``qdil.rewards.builtin.GAIL``) is followed to the module
    that defines it.

    Args:
        class_path: ``package.module.Class``.

    Returns:
        The registry name, or None when the module's source cannot be found or the class is
        not decorated there (registered some other way, or not at all).
    """
    for _ in range(4):  # re-exports followed at most this deep
        module, _, qualname = class_path.rpartition(".")
        if not module:
            return None
        origin = module_source(module)
        if origin is None:
            return None
        names, imported = _declared(origin)
        if qualname in names:
            return names[qualname]
        if qualname not in imported:
            return None
        class_path = imported[qualname]
    return None


@cache
def _declared(path: str) -> tuple[dict[str, str], dict[str, str]]:
    """What the module at ``path`` declares and imports.

    Returns:
        ``{class: registry name}`` of its decorated top-level classes, and
        ``{name: "module.name"}`` of what it imports by absolute ``from`` imports.
    """
    try:
        tree = ast.parse(Path(path).read_text(encoding="utf-8"))
    except (OSError, SyntaxError, UnicodeDecodeError):
        return {}, {}
    names, imported = {}, {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for alias in node.names:
                imported[alias.asname or alias.name] = f"{node.module}.{alias.name}"
        if not isinstance(node, ast.ClassDef):
            continue
        for decorator in node.decorator_list:
            if is_register_call(decorator):
                names[node.name] = decorator.args[0].value
    return names, imported


def named_reward(name: str) -> type:
    """The reward model registered as ``name``, or whose class is named ``name`` (``GAIL``).

    Raises:
        ValueError: for neither, listing the registered names.
    """
    from qdil.rewards import get_reward, list_rewards

    if name != name.lower():  # registered names are lowercase: a class name
        classes = {entry.cls for entry in list_rewards() if entry.cls.__name__ == name}
        if len(classes) == 1:
            return classes.pop()
    return get_reward(name)


def resolve_reward_names(config: dict) -> dict:
    """Turn a registered reward name (``reward: gail``) or class name into its class path."""
    reward = config.get("reward")
    if isinstance(reward, str) and "." not in reward:
        cls = named_reward(reward)
        config["reward"] = {"class_path": f"{cls.__module__}.{cls.__qualname__}"}
    elif isinstance(reward, dict) and "." not in str(reward.get("class_path", ".")):
        cls = named_reward(reward["class_path"])
        config["reward"] = {**reward, "class_path": f"{cls.__module__}.{cls.__qualname__}"}
    return config


def rewrite_reward_flag(argv: list[str]) -> list[str]:
    """``--reward gail`` / ``--reward.help GAIL`` (a registered or class name) -> class path."""
    out = list(argv)
    for i, arg in enumerate(out):
        value = None
        if arg in ("--reward", "--reward.help") and i + 1 < len(out):
            value, index = out[i + 1], i + 1
        elif arg.startswith(("--reward=", "--reward.help=")):
            value, index = arg.split("=", 1)[1], i
        if value and "." not in value and value.isidentifier():
            cls = named_reward(value)
            path = f"{cls.__module__}.{cls.__qualname__}"
            out[index] = path if index == i + 1 else f"{arg.split('=', 1)[0]}={path}"
    return out


def drop_form_on_switch(content: dict[str, Any], argv: list[str]) -> dict[str, Any]:
    """The recipe without its ``reward_form`` when ``argv`` switches the reward model.

    A switched model keeps the recipe's shared training options but takes its own default
    form (each model's score has its own scale), unless ``argv`` sets the form as well.
    """
    flags = [arg.split("=", 1)[0] for arg in argv]
    if "--reward" not in flags or any(flag.endswith(".reward_form") for flag in flags):
        return content
    reward = content.get("reward")
    args = reward.get("init_args") if isinstance(reward, dict) else None
    if isinstance(args, dict) and "reward_form" in args:
        content = {**content, "reward": {**reward, "init_args": dict(args)}}
        del content["reward"]["init_args"]["reward_form"]
    return content
