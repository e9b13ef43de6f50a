"""Statistics of a report: mean ± std over seeds, Tukey HSD between methods, aligned curves.

- Spread is the **sample** standard deviation (``ddof=1``) over seeds. With one seed it is
  undefined: the text shows the mean alone with ``(n=1)`` (the CSV keeps std 0).
- Tukey's HSD (``scipy.stats.tukey_hsd``) compares every pair of methods of one task on the
  raw QD-Score. It needs at least two methods with at least two seeds each; methods with
  fewer seeds are left out of the test and named in a note.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import tukey_hsd

ALPHA = 0.05
"""Significance level of the Tukey table: p ≤ ALPHA is marked in bold."""


@dataclass(frozen=True)
class Summary:
    """Mean and sample standard deviation of one metric over seeds.

    Attributes:
        mean: the mean over seeds (NaN for no seeds).
        std: sample standard deviation (``ddof=1``); 0 for a single seed.
        n: number of seeds.
    """

    mean: float
    std: float
    n: int


def summarize(values: Sequence[float] | np.ndarray) -> Summary:
    """Mean ± sample std of values over seeds.

    Args:
        values: one number per seed, shape ``(n,)``.

    Returns:
        The summary; ``std`` uses ``ddof=1`` when ``n > 1`` and is 0 for ``n == 1``.
    """
    array = np.asarray(values, dtype=np.float64).reshape(-1)
    n = len(array)
    if n == 0:
        return Summary(math.nan, math.nan, 0)
    std = float(np.std(array, ddof=1)) if n > 1 else 0.0
    return Summary(float(np.mean(array)), std, n)


def format_number(value: float, style: str) -> str:
    """One number the way the paper prints it.

    Args:
        value: the number.
        style: ``"sci"`` (``3.80e+06``, QD-Scores), ``"fixed"`` (``98.28``, coverage in %)
            or ``"int"`` (``4,553``, returns).

    Returns:
        The text; ``nan`` for a missing value.
    """
    if not math.isfinite(value):
        return "nan"
    if style == "sci":
        return f"{value:.2e}"
    if style == "fixed":
        return f"{value:.2f}"
    if style == "int":
        return f"{value:,.0f}"
    raise ValueError(f"style must be sci, fixed or int, got {style!r}")


def format_mean_std(summary: Summary, style: str) -> str:
    """``mean ± std`` text of a summary; a single seed reads ``mean (n=1)``, no spread.

    Args:
        summary: the summary.
        style: see :func:`format_number`.
    """
    if summary.n == 0:
        return "–"
    mean = format_number(summary.mean, style)
    if summary.n == 1:
        return f"{mean} (n=1)"
    return f"{mean} ± {format_number(summary.std, style)}"


@dataclass(frozen=True)
class Comparison:
    """One pair of a Tukey HSD test.

    Attributes:
        group1: the first method (sorted order).
        group2: the second method.
        mean1: mean of group1.
        mean2: mean of group2.
        diff: ``mean2 - mean1``.
        pvalue: Tukey-adjusted p-value.
        n1: seeds of group1.
        n2: seeds of group2.
    """

    group1: str
    group2: str
    mean1: float
    mean2: float
    diff: float
    pvalue: float
    n1: int
    n2: int

    @property
    def sign(self) -> str:
        """``+`` when group2's mean is higher, ``-`` when lower, ``0`` when equal."""
        return "+" if self.diff > 0 else "-" if self.diff < 0 else "0"

    @property
    def significant(self) -> bool:
        """Whether ``pvalue ≤ ALPHA``."""
        return bool(self.pvalue <= ALPHA)


@dataclass
class TukeyResult:
    """Tukey HSD over the methods of one task.

    Attributes:
        comparisons: every pair of tested methods (empty when the test was skipped).
        notes: why methods, or the whole test, were left out.
    """

    comparisons: list[Comparison] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def tukey(groups: Mapping[str, Sequence[float] | np.ndarray]) -> TukeyResult:
    """Tukey HSD between every pair of groups (``scipy.stats.tukey_hsd``).

    Groups are sorted by name (as Python sorts strings); each pair ``(group1, group2)`` has
    ``group1`` before ``group2`` and ``diff = mean(group2) - mean(group1)``, so the sign of
    the paper's table is ``+`` when group2 is better.

    Args:
        groups: method name -> values over seeds, each of shape ``(n_method,)``.

    Returns:
        The comparisons and notes; no comparisons when fewer than two groups have at least
        two values.
    """
    result = TukeyResult()
    tested: dict[str, np.ndarray] = {}
    for name in sorted(groups):
        values = np.asarray(groups[name], dtype=np.float64).reshape(-1)
        if len(values) < 2:
            result.notes.append(
                f"{name} left out of the Tukey HSD test: {len(values)} seed(s), needs 2"
            )
        elif not np.all(np.isfinite(values)):
            result.notes.append(f"{name} left out of the Tukey HSD test: non-finite values")
        else:
            tested[name] = values
    if len(tested) < 2:
        result.notes.append(
            f"Tukey HSD skipped: needs at least 2 methods with at least 2 seeds each, "
            f"found {len(tested)}"
        )
        return result
    names = list(tested)
    test = tukey_hsd(*tested.values())
    if not np.all(np.isfinite(test.pvalue)):
        result.notes.append("some p-values are undefined (no variance within the groups)")
    for i, first in enumerate(names):
        for j in range(i + 1, len(names)):
            second = names[j]
            mean1, mean2 = float(np.mean(tested[first])), float(np.mean(tested[second]))
            result.comparisons.append(
                Comparison(
                    group1=first,
                    group2=second,
                    mean1=mean1,
                    mean2=mean2,
                    diff=mean2 - mean1,
                    pvalue=float(test.pvalue[i, j]),
                    n1=len(tested[first]),
                    n2=len(tested[second]),
                )
            )
    return result


def align_curves(
    curves: Sequence[tuple[np.ndarray, np.ndarray]],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean and spread over seeds of curves logged at possibly different iterations.

    Only iterations that every seed has are kept (a shorter seed shortens the curve).

    Args:
        curves: per seed, ``(iterations, values)``, both of shape ``(T_seed,)``.

    Returns:
        ``(iterations, mean, std)``, each of shape ``(T,)``: the common iterations in
        increasing order, the mean over seeds, and the sample std (``ddof=1``; zeros for a
        single seed).
    """
    if not curves:
        empty = np.zeros(0)
        return empty, empty, empty
    common = set(np.asarray(curves[0][0]).tolist())
    for iterations, _ in curves[1:]:
        common &= set(np.asarray(iterations).tolist())
    steps = np.array(sorted(common), dtype=np.float64)
    stacked = np.zeros((len(curves), len(steps)))
    for row, (iterations, values) in enumerate(curves):
        lookup = dict(zip(np.asarray(iterations).tolist(), np.asarray(values), strict=True))
        stacked[row] = [lookup[step] for step in steps.tolist()]
    mean = stacked.mean(axis=0) if len(steps) else np.zeros(0)
    std = stacked.std(axis=0, ddof=1) if len(curves) > 1 else np.zeros_like(mean)
    return steps, mean, std
