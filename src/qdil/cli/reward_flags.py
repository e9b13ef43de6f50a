"""The reward section by name: registered and class names in recipes and on the command line.

``reward: gail`` and ``--reward GAIL`` become class paths before jsonargparse parses them,
and a switch of model on the command line leaves the recipe's reward form behind.
"""

from __future__ import annotations

from typing import Any


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
