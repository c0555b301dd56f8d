"""Compare the learning curves of finished runs (e.g. flat vs given options) in one figure.

    python benchmarks/compare_curves.py runs/flat runs/given --labels flat "given options" \\
        --out runs/compare.png

Each argument is a run directory written by ``skillchain train`` (or ``DIR1+DIR2``, their runs
stacked: a population split over processes) (``returns.npy``; for a run
still in progress, ``--partial`` reads the returns of its latest checkpoint and keeps only the
episodes every run has completed). The figure shows every run's mean return per episode with
its 95% interval over runs (mean +- 1.96 sd / sqrt(n)). The table gives, per episode window,
the mean over runs of each run's mean return in the window, +- its standard error
(sd / sqrt(runs)), and the difference of each run from the first with its Welch standard error.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.outputs.plots import plot_learning_curve
from skillchain_torch.trainers.study.summary import window_stats

DEFAULT_WINDOWS = "1-5,6-10,11-20,21-40"


def parse_windows(text: str) -> list[tuple[int, int]]:
    """``"1-5,6-10"`` -> ``[(1, 5), (6, 10)]`` (1-based, inclusive)."""
    windows = []
    for part in text.split(","):
        first, _, last = part.strip().partition("-")
        first, last = int(first), int(last or first)
        if not 1 <= first <= last:
            raise ValueError(f"bad episode window {part!r}")
        windows.append((first, last))
    return windows


def load_returns(run_dir: str | Path, partial: bool = False) -> tuple[np.ndarray, dict]:
    """``(returns [runs, episodes], config dict)`` of a run directory; ``"A+B"`` stacks the
    runs of directories A and B (e.g. one population split over two processes with seeds 0
    and 10: by the seed contract they are the runs of one population with seed 0)."""
    parts = str(run_dir).split("+")
    if len(parts) > 1:
        loaded = [load_returns(part, partial) for part in parts]
        episodes = min(r.shape[1] for r, _ in loaded)
        return np.concatenate([r[:, :episodes] for r, _ in loaded]), loaded[0][1]
    run = Path(run_dir)
    config = json.loads((run / "config.json").read_text()) if (run / "config.json").is_file() \
        else {}
    if (run / "returns.npy").is_file():
        returns = np.load(run / "returns.npy")
    elif partial:
        from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint, read_checkpoint

        path = latest_checkpoint(run)
        if path is None:
            raise ValueError(f"{run}: no returns.npy and no checkpoint")
        returns = read_checkpoint(path)["trainer"]["returns"].numpy()
    else:
        raise ValueError(f"{run}: no returns.npy (unfinished? try --partial)")
    done = ~np.isnan(returns).any(axis=0)
    episodes = int(np.argmin(done)) if not done.all() else returns.shape[1]
    return returns[:, :episodes], config


def comparison_table(curves: dict[str, np.ndarray], windows) -> str:
    """A Markdown table: mean +- s.e. per window and run, and the differences from the first."""
    names = list(curves)
    header = "| episodes | " + " | ".join(names)
    header += "".join(f" | {n} - {names[0]}" for n in names[1:]) + " |"
    lines = [header, "|" + "---|" * (1 + 2 * len(names) - 1)]
    for first, last in windows:
        if any(r.shape[1] < last for r in curves.values()):
            continue
        cells, stats = [], {}
        for name, r in curves.items():
            mean, se = window_stats(r, first, last)
            stats[name] = (mean, se)
            cells.append(f"{mean:,.0f} +- {se:,.0f}")
        base = stats[names[0]]
        for name in names[1:]:
            mean, se = stats[name]
            cells.append(f"{mean - base[0]:+,.0f} +- {math.hypot(se, base[1]):,.0f}")
        lines.append(f"| {first}-{last} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def spread_table(curves: dict[str, np.ndarray], windows, good: float = 9000.0) -> str:
    """Consistency across runs: per window, the standard deviation over runs of each run's
    mean return, and the share of episodes with a return of at least ``good``."""
    names = list(curves)
    header = "| episodes | " + " | ".join(f"{n}: sd over runs, share >= {good:,.0f}"
                                          for n in names) + " |"  # fmt: skip
    lines = [header, "|" + "---|" * (1 + len(names))]
    for first, last in windows:
        if any(r.shape[1] < last for r in curves.values()):
            continue
        cells = []
        for r in curves.values():
            window = r[:, first - 1 : last]
            per_run = window.mean(axis=1)
            cells.append(f"{per_run.std(ddof=1):,.0f}, {(window >= good).mean():.2f}")
        lines.append(f"| {first}-{last} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def save_comparison(curves: dict[str, np.ndarray], path: str | Path,
                    title: str | None = None) -> Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 4.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for i, (name, returns) in enumerate(curves.items()):
        plot_learning_curve(returns, ax=ax, label=f"{name} ({returns.shape[0]} runs)",
                            color=f"C{i}")
    handles, labels = ax.get_legend_handles_labels()
    keep = [i for i, label in enumerate(labels) if label != "95% interval"]
    ax.legend([handles[i] for i in keep], [labels[i] for i in keep], loc="lower right",
              title="mean, 95% interval")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="run directories (DIR1+DIR2 stacks runs)")
    parser.add_argument("--labels", nargs="+", default=None, help="one label per run")
    parser.add_argument("--out", type=Path, default=Path("compare_curves.png"))
    parser.add_argument("--windows", default=DEFAULT_WINDOWS,
                        help=f"episode windows (default {DEFAULT_WINDOWS})")
    parser.add_argument("--partial", action="store_true",
                        help="read unfinished runs from their latest checkpoint")
    parser.add_argument("--title", default=None)
    args = parser.parse_args(argv)
    labels = args.labels or [Path(p.split("+")[0]).name for p in args.runs]
    if len(labels) != len(args.runs):
        parser.error(f"{len(labels)} labels for {len(args.runs)} runs")
    try:
        windows = parse_windows(args.windows)
        loaded = [load_returns(p, args.partial) for p in args.runs]
    except (ValueError, OSError) as err:
        parser.error(str(err))
    curves = {label: r for label, (r, _) in zip(labels, loaded)}
    maps = {c.get("map") for _, c in loaded}
    seeds = {c.get("seed") for _, c in loaded}
    title = args.title or f"{', '.join(map(str, maps))} (seed {', '.join(map(str, seeds))})"
    save_comparison(curves, args.out, title=title)
    for label, r in curves.items():
        print(f"{label}: {r.shape[0]} runs x {r.shape[1]} episodes")
    print()
    print(comparison_table(curves, windows))
    print()
    print(spread_table(curves, windows))
    print(f"\nfigure: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
