"""The laptop Walker2d expert confirmation's rule, applied to its records.

``python benchmarks/probes/expert_confirmation.py`` reads the re-scored archives of
docs/reports/walker-expert-confirmation/runs and prints, per arm, the corrected coverage,
QD-Score and best return over seeds 5-7, the one-sided Welch test of the protocol
(docs/expert-search-protocol.md, section 2), the best-return ratio and the coverage ratio
with a 95 % bootstrap interval (10,000 resamples of seeds per arm, random state 0).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy import stats

RUNS = Path(__file__).resolve().parents[2] / "docs/reports/walker-expert-confirmation/runs"
ARMS = {"recipe": "walker_ppga-seed{}", "candidate": "walker_ppga-db6436fa-seed{}"}
SEEDS = (5, 6, 7)


def metrics(arm: str) -> dict[str, np.ndarray]:
    rows = [json.loads((RUNS / ARMS[arm].format(s) / "eval.json").read_text()) for s in SEEDS]
    return {k: np.array([r["metrics"][k] for r in rows]) for k in rows[0]["metrics"]}


def main() -> None:
    arms = {arm: metrics(arm) for arm in ARMS}
    for arm, m in arms.items():
        print(arm)
        for key, scale in (("coverage", 100), ("qd_score", 1), ("obj_max", 1), ("obj_mean", 1)):
            v = m[key] * scale
            print(f"  {key}: {np.round(v, 2)} mean {v.mean():.2f} std {v.std(ddof=1):.2f}")
    cand, rec = arms["candidate"]["coverage"], arms["recipe"]["coverage"]
    test = stats.ttest_ind(cand, rec, equal_var=False, alternative="greater")
    print(f"rule 1, coverage: one-sided Welch t = {test.statistic:.3f}, p = {test.pvalue:.4f}")
    best = arms["candidate"]["obj_max"].mean() / arms["recipe"]["obj_max"].mean()
    print(f"rule 2, best: {best:.3f} of the recipe's (at least 0.9 needed)")
    rng = np.random.RandomState(0)
    draws = [
        rng.choice(cand, cand.size).mean() / rng.choice(rec, rec.size).mean() for _ in range(10_000)
    ]
    low, high = np.percentile(draws, [2.5, 97.5])
    print(f"coverage ratio {cand.mean() / rec.mean():.3f}, 95 % bootstrap [{low:.3f}, {high:.3f}]")
    verdict = test.pvalue < 0.05 and best >= 0.9
    print("better by the protocol's rule" if verdict else "not better by the protocol's rule")


if __name__ == "__main__":
    main()
