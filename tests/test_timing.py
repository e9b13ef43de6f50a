"""qdil.timing: the loop's sections totalled on request, nothing counted otherwise."""

from __future__ import annotations

from pathlib import Path

import pytest

from qdil import timing

ROOT = Path(__file__).resolve().parents[1]


def test_sections_count_only_while_recording_and_a_nested_same_name_once() -> None:
    ticks = iter(range(100))

    def clock() -> float:
        return float(next(ticks))

    @timing.timed("outer")
    def outer() -> None:
        # the same name inside: counted once, by the outermost
        with timing.section("outer"), timing.section("inner"):
            pass

    outer()  # not recording: no clock read
    with timing.recording(clock) as seconds:
        outer()
    # clock reads: outer starts 0, inner 1 -> 2, outer ends 3
    assert seconds == {"outer": 3.0, "inner": 1.0}
    outer()
    assert seconds == {"outer": 3.0, "inner": 1.0}  # the record is closed
    with (
        pytest.raises(RuntimeError, match="already recording"),
        timing.recording(),
        timing.recording(),
    ):
        pass


def test_a_step_of_an_imitation_run_fills_every_section(tmp_path: Path) -> None:
    import time

    import qdil

    recipe = ROOT / "recipes" / "smoke" / "walker_il.yaml"
    settings = ["--logging.wandb", "disabled", "--logging.progress", "false"]
    settings += ["--demos.path", "walker2d"]  # the shipped demonstrations
    with qdil.Experiment.from_recipe(recipe, settings, root=tmp_path) as run:
        run.step()  # compiles and warms up
        with timing.recording(time.process_time) as seconds:
            run.step()
    assert set(seconds) == set(timing.SECTIONS), seconds
    assert all(value > 0 for value in seconds.values()), seconds
