"""The recipe's schema read from source equals the one the parser builds from the classes."""

from __future__ import annotations

import dataclasses
import inspect

import pytest

import qdil.recipe
from qdil.recipe_schema import schema, unknown_keys


def test_the_schema_read_from_source_is_the_recipes() -> None:
    read = schema()
    assert read is not None
    parameters = inspect.signature(qdil.recipe.recipe).parameters
    assert read.sections == tuple(parameters)
    sections = {}
    for name, parameter in parameters.items():
        annotation = eval(parameter.annotation, vars(qdil.recipe))
        if dataclasses.is_dataclass(annotation):
            sections[name] = tuple(field.name for field in dataclasses.fields(annotation))
    assert read.keys == sections
    assert {"env", "qd", "logging", "bonus", "demos", "policy"} <= set(sections)


@pytest.mark.parametrize(
    ("content", "overrides", "message"),
    [
        ({"rewrd": "gail"}, [], "unknown section 'rewrd' in the recipe; did you mean 'reward'?"),
        ({"env": {"num_env": 3}}, [], "unknown key 'env.num_env' in the recipe; did you mean"),
        ({}, ["--qd.itrations", "5"], "unknown key 'qd.itrations' in --qd.itrations; did you"),
        ({}, ["--sed=3"], "unknown section 'sed' in --sed; did you mean 'seed'?"),
        ({}, ["--logging.xyz", "1"], "unknown key 'logging.xyz' in --logging.xyz; the keys of"),
    ],
)
def test_unknown_sections_and_keys_are_named_with_the_closest(content, overrides, message):
    problems = unknown_keys(content, overrides)
    assert len(problems) == 1
    assert problems[0].startswith(message)


def test_known_keys_and_the_keys_of_classes_pass() -> None:
    """A class-valued section's keys are its class's: left to the full parser."""
    content = {
        "reward": {"class_path": "gail", "init_args": {"anything": 1}},
        "env": {"task": "Hopper-v5", "num_envs": 4},
        "qd": {"archive": {"type": "cvt"}, "emitter": {"init_args": {"batch_size": 4}}},
        "seed": 1,
    }
    overrides = ["--config", "x.yaml", "--reward.hidden", "8", "--qd.archive.type", "grid"]
    assert unknown_keys(content, [*overrides, "--rl.init_args.gamma=0.9", "8"]) == []
