"""The QD baselines protocol's reading, applied to its report (docs/qd-baselines-protocol.md).

``python benchmarks/probes/qd_baselines_reading.py`` reads docs/reports/walker-qd-baselines/runs.csv
(the corrected archives of PPGA, CMA-MAEGA (ES) and sep-CMA-MAE, seeds 5-7) and prints, per
baseline and metric (corrected QD-Score, coverage, best return), the ratio of means to
PPGA's with its 95 % bootstrap interval (qdil's ``ratio_of_means``: 10,000 resamples of
seeds per arm, random state ``BOOTSTRAP_SEED``) and Welch's two-sided test.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from scipy import stats

from qdil.evaluation.ratios import ratio_of_means

RUNS = Path(__file__).resolve().parents[2] / "docs/reports/walker-qd-baselines/runs.csv"
METRICS = {"qd_score": "QD-Score", "coverage_pct": "coverage", "obj_max": "best"}
BASELINES = ("CMA-MAEGA (ES)", "sep-CMA-MAE")


def main() -> None:
    with open(RUNS, newline="") as file:
        rows = [r for r in csv.DictReader(file) if r["status"] == "included"]
    values = {
        (method, key): np.array([float(r[key]) for r in rows if r["method"] == method])
        for method in ("PPGA", *BASELINES)
        for key in METRICS
    }
    print("| baseline | metric | seeds | ratio to PPGA | 95 % interval | Welch p | shown |")
    print("|---|---|---|---|---|---|---|")
    for method in BASELINES:
        for key, label in METRICS.items():
            a, b = values[method, key], values["PPGA", key]
            ratio = ratio_of_means(a, b)
            p = stats.ttest_ind(a, b, equal_var=False).pvalue
            shown = "yes" if ratio.low > 1 or ratio.high < 1 else "no"
            print(
                f"| {method} | {label} | {len(a)}/{len(b)} | {ratio.value:.2f} | "
                f"[{ratio.low:.2f}, {ratio.high:.2f}] | {p:.3f} | {shown} |"
            )


if __name__ == "__main__":
    main()
