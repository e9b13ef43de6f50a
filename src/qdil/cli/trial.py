"""A trial's commands in one child process: ``qdil fit``, then ``qdil eval`` where it is due.

Each command is the one a user would type, run through the same entry point in the same
order, so the trial's run equals ``qdil fit``'s and its ``eval.json`` equals ``qdil eval``'s;
one process pays the imports once. The trial's log gets each command's start and end.

Run as ``python -m qdil.cli.trial RUN_DIR EPISODES fit ARGS...``; the re-scoring takes
the fit's ``--env.num_threads``.
"""

from __future__ import annotations

import sys
from pathlib import Path

from qdil.sweeps.trainable import now, rescored


def main(argv: list[str]) -> None:
    """Fit the run, then re-score it on ``EPISODES`` episodes per elite unless that is done."""
    from qdil.cli import main as qdil

    run_dir, episodes, *fit = argv
    qdil(fit)
    if int(episodes) and not rescored(Path(run_dir), int(episodes)):
        threads = fit[fit.index("--env.num_threads") + 1]
        command = ["eval", run_dir, "--episodes", episodes, "--num-threads", threads]
        sys.stderr.flush()
        print(f"# ended {now()} with exit status 0", flush=True)
        print(f"$ qdil {' '.join(command)}\n# started {now()}", flush=True)
        qdil(command)


if __name__ == "__main__":
    main(sys.argv[1:])
