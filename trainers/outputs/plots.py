"""The learning-curve figure: mean return per episode with a 95% interval over runs.

Example:
    >>> import numpy as np, matplotlib
    >>> matplotlib.use("Agg")
    >>> ax = plot_learning_curve(np.random.default_rng(0).normal(size=(5, 20)), label="flat")
    >>> len(ax.lines), len(ax.collections)
    (1, 1)
"""

from __future__ import annotations

import functools
import warnings
from pathlib import Path

import numpy as np

__all__ = ["learning_curve", "plot_learning_curve", "save_learning_curve", "t95"]


@functools.cache
def t95(n: int) -> float:
    """Student's two-sided 95% quantile for the mean of ``n`` runs (``t(0.975, n - 1)``; 0 for
    fewer than 2 runs, where no interval exists)."""
    from skillchain_torch.trainers.study.intervals import (
        t_quantile,  # (the study package imports nothing heavy)
    )

    return t_quantile(0.975, n - 1) if n > 1 else 0.0


def learning_curve(returns) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-episode ``(mean, low, high)`` over runs of ``returns [runs, episodes]``: mean +-
    t(n - 1) sd / sqrt(n), Student's 95% interval with n the runs that completed the episode
    (NaN = not completed); with 10 runs t is 2.262, 15% wider than the normal's 1.96."""
    r = np.asarray(returns, dtype=np.float64)
    if r.ndim != 2:
        raise ValueError(f"returns must be [runs, episodes], got shape {r.shape}")
    n = np.sum(~np.isnan(r), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # sd of a single run
        mean = np.nanmean(r, axis=0) if r.size else np.zeros(r.shape[1])
        sd = np.nanstd(r, axis=0, ddof=1) if r.shape[0] > 1 else np.zeros(r.shape[1])
        t = np.array([t95(k) for k in n.tolist()])
        half = np.where(n > 1, t * sd / np.sqrt(np.maximum(n, 1)), 0.0)
    return mean, mean - half, mean + half


def plot_learning_curve(returns, ax=None, label: str | None = None, color: str | None = None,
                        title: str | None = None):
    """Draw the mean return per episode and its 95% band; returns the matplotlib ``Axes``."""
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(7, 4.5))
    mean, low, high = learning_curve(returns)
    episodes = np.arange(1, mean.size + 1)
    runs = np.asarray(returns).shape[0]
    (line,) = ax.plot(episodes, mean, label=label or f"mean of {runs} runs", color=color, lw=1.5)
    ax.fill_between(episodes, low, high, color=line.get_color(), alpha=0.25, lw=0,
                    label="95% interval")
    ax.set_xlabel("episode")
    ax.set_ylabel("return")
    if title:
        ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    return ax


def save_learning_curve(returns, path: str | Path, title: str | None = None,
                        reference: tuple[str, np.ndarray] | None = None) -> Path:
    """Write the learning-curve figure to ``path`` (PNG through matplotlib's Agg backend).

    ``reference``: ``(label, returns)`` of another run drawn beside it on the same episodes
    (the demo draws the committed flat study's), so that learning is visible against it. With
    few runs a 95% band can span far beyond the curves; the axis then follows the means, and
    the figure says that the band is cut."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 4.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    returns = np.asarray(returns, dtype=np.float64)
    means = [learning_curve(returns)]
    if reference is not None:
        label, ref = reference
        ref = np.asarray(ref, dtype=np.float64)[:, :returns.shape[1]]
        plot_learning_curve(ref, ax=ax, label=label, color="0.45")
        means.append(learning_curve(ref))
    plot_learning_curve(returns, ax=ax, title=title, color="C0",
                        label=f"this run, mean of {returns.shape[0]} runs")
    handles, labels = ax.get_legend_handles_labels()
    keep = [i for i, text in enumerate(labels) if text != "95% interval"]
    ax.legend([handles[i] for i in keep], [labels[i] for i in keep], loc="lower right",
              title="mean, 95% band")
    finite = [m[np.isfinite(m)] for m, _, _ in means]
    low_band = min(float(np.nanmin(lo)) for _, lo, _ in means)
    high_band = max(float(np.nanmax(hi)) for _, _, hi in means)
    if all(f.size for f in finite):
        lo, hi = min(float(f.min()) for f in finite), max(float(f.max()) for f in finite)
        pad = 0.15 * max(hi - lo, 1.0)
        if low_band < lo - 2 * pad or high_band > hi + 2 * pad:  # a band far wider than the means
            ax.set_ylim(lo - pad, hi + pad)
            ax.text(0.01, 0.99, "axis follows the means; the 95% band is cut",
                    transform=ax.transAxes, va="top", fontsize=8, color="0.3")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    return path
