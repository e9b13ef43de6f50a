"""Does one method at least match another? The clip protocol's second Humanoid target.

``python benchmarks/probes/match_reading.py RECORDS --method humanoid_mcwae_clip --against
humanoid_gail_absorbing`` reads the ``eval.json`` of every run under RECORDS whose name is
``METHOD-seedN`` or ``AGAINST-seedN`` and prints, for the true-keyed and the deployable
archive, each method's corrected QD-Scores over its seeds, their mean and standard
deviation, the protocol's reading (docs/evidence-protocol.md, "The critic's inputs
clipped": METHOD's mean no lower than AGAINST's less one AGAINST standard deviation), the
paper's ordering (METHOD's mean at least AGAINST's) and the ratio of means with its 95 %
bootstrap interval (``qdil.evaluation.ratios.ratio_of_means``, as reports compute it).
"""

from __future__ import annotations

import argparse
import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from qdil.evaluation.ratios import ratio_of_means

SEEDED = re.compile(r"^(?P<method>.+)-seed(?P<seed>\d+)$")


@dataclass(frozen=True)
class Match:
    """``method`` against ``against`` on one archive's corrected QD-Scores (seed -> score)."""

    archive: str
    method: dict[int, float]
    against: dict[int, float]

    @property
    def means(self) -> tuple[float, float]:
        return float(np.mean(list(self.method.values()))), float(
            np.mean(list(self.against.values()))
        )

    @property
    def against_std(self) -> float:
        """AGAINST's standard deviation over its seeds (ddof 1; NaN with one seed)."""
        scores = list(self.against.values())
        return float(np.std(scores, ddof=1)) if len(scores) > 1 else float("nan")

    @property
    def protocol_met(self) -> bool:
        mine, theirs = self.means
        return mine >= theirs - self.against_std

    @property
    def ordering_met(self) -> bool:
        mine, theirs = self.means
        return mine >= theirs


def scores(records: Path, method: str) -> tuple[dict[int, float], dict[int, float]]:
    """Seed -> corrected QD-Score of ``method``'s runs: (true-keyed, deployable).

    Raises:
        ValueError: no run of ``method`` under ``records``, or one not re-scored.
    """
    true: dict[int, float] = {}
    deployable: dict[int, float] = {}
    for run in sorted(records.iterdir()):
        named = SEEDED.match(run.name)
        if not named or named["method"] != method:
            continue
        path = run / "eval.json"
        if not path.is_file():
            raise ValueError(f"{run}: no eval.json; re-score it first (qdil eval {run})")
        record = json.loads(path.read_text())
        seed = int(named["seed"])
        true[seed] = float(record["metrics"]["qd_score"])
        deployable[seed] = float(record["deployable"]["metrics"]["qd_score"])
    if not true:
        raise ValueError(f"no run named {method}-seedN under {records}")
    return true, deployable


def matches(records: Path, method: str, against: str) -> list[Match]:
    """The true-keyed and the deployable archives' :class:`Match`."""
    mine, theirs = scores(records, method), scores(records, against)
    archives = ("true", "deployable")
    return [Match(name, m, t) for name, m, t in zip(archives, mine, theirs, strict=True)]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("records", type=Path, help="folder of run folders or run records")
    parser.add_argument("--method", required=True, help="run name before -seedN (the imitator)")
    parser.add_argument("--against", required=True, help="run name before -seedN (its rival)")
    args = parser.parse_args(argv)
    if not args.records.is_dir():
        parser.error(f"RECORDS {args.records} is not a folder")
    try:
        found = matches(args.records, args.method, args.against)
    except ValueError as error:
        parser.error(str(error))
    print(
        "| archive | method QD-Scores | mean | against QD-Scores | mean ± std "
        "| mean ≥ against's − 1 std | mean ≥ against's | ratio of means [95 % bootstrap] |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for m in found:
        mine, theirs = m.means
        ratio = ratio_of_means(list(m.method.values()), list(m.against.values()))
        listed = lambda d: ", ".join(f"{v:.3g} (seed {s})" for s, v in d.items())  # noqa: E731
        print(
            f"| {m.archive} | {listed(m.method)} | {mine:.3g} | {listed(m.against)} "
            f"| {theirs:.3g} ± {m.against_std:.2g} | {'met' if m.protocol_met else 'missed'} "
            f"| {'met' if m.ordering_met else 'missed'} "
            f"| {ratio.value:.2f} [{ratio.low:.2f}, {ratio.high:.2f}] |"
        )


if __name__ == "__main__":
    main()
