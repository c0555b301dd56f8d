"""Compare the learning curves of finished runs (e.g. flat vs skill chaining) in one figure.

    skillchain plot runs/flat runs/sc --labels flat "skill chaining" --out runs/compare.png

Each argument is a run directory written by ``skillchain train`` (or ``DIR1+DIR2``, their runs
stacked: a population split over processes) (``returns.npy``; for a run still in progress,
``--partial`` reads the returns of its latest checkpoint and keeps only the episodes every run
has completed). The figure shows every run's mean return per episode with its 95% interval over
runs. The table gives, per episode window, the mean over runs of each run's mean return in the
window with its 95% t interval, and each run minus the first with Welch's 95% interval (``*``:
the interval excludes 0). The default windows are the paper report's (1-10, 26-50, 51-100, ...)
that the runs reach, or four equal parts of a shorter run.

Example:
    >>> import numpy as np
    >>> curves = {"a": np.zeros((3, 8)), "b": np.ones((3, 8)) * [[1.0], [2.0], [3.0]]}
    >>> print(comparison_table(curves, [(1, 8)]))  # doctest: +NORMALIZE_WHITESPACE
    | episodes | a | b | b - a |
    |---|---|---|---|
    | 1-8 | 0 +- 0 | 2 +- 2 | +2 +- 2 |
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.outputs.plots import plot_learning_curve
from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci

__all__ = ["comparison_table", "default_windows", "load_returns", "main", "parse_windows",
           "save_comparison", "spread_table"]

PAPER_WINDOWS = ((1, 10), (26, 50), (51, 100), (101, 150), (151, 200), (201, 250))


def default_windows(episodes: int) -> list[tuple[int, int]]:
    """The paper report's windows the runs reach (at least two), else four equal parts."""
    paper = [w for w in PAPER_WINDOWS if w[1] <= episodes]
    if len(paper) >= 2:
        return paper
    edges = np.linspace(0, episodes, 5).round().astype(int)
    return [(int(a) + 1, int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]


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
    """A Markdown table: per window and run, the mean with its 95% t interval, and each run
    minus the first with Welch's 95% interval (``*``: it excludes 0)."""
    names = list(curves)
    header = "| episodes | " + " | ".join(names)
    header += "".join(f" | {n} - {names[0]}" for n in names[1:]) + " |"
    lines = [header, "|" + "---|" * (1 + 2 * len(names) - 1)]
    for first, last in windows:
        if any(r.shape[1] < last for r in curves.values()):
            continue
        cells = []
        per_run = {name: r[:, first - 1:last].mean(axis=1) for name, r in curves.items()}
        for name in names:
            mean, half = mean_ci(per_run[name])
            cells.append(f"{mean:,.0f} +- {half:,.0f}")
        for name in names[1:]:
            diff, half = diff_ci(per_run[name], per_run[names[0]])
            star = " *" if abs(diff) > half else ""
            cells.append(f"{diff:+,.0f} +- {half:,.0f}{star}")
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
    parser = argparse.ArgumentParser(prog="skillchain plot", description=__doc__.splitlines()[0])
    add_plot_arguments(parser)
    return run_plot(parser, parser.parse_args(argv))


def add_plot_arguments(parser) -> None:
    """``skillchain plot``'s arguments."""
    parser.add_argument("runs", nargs="+", help="run directories (DIR1+DIR2 stacks runs)")
    parser.add_argument("--labels", nargs="+", default=None,
                        help="one label per run (default: the folders' names)")
    parser.add_argument("--out", type=Path, default=Path("compare.png"),
                        help="the figure (default compare.png)")
    parser.add_argument("--windows", default=None,
                        help="episode windows, e.g. 1-10,26-50 (default: the paper report's "
                        "that the runs reach, else four equal parts)")
    parser.add_argument("--partial", action="store_true",
                        help="read unfinished runs from their latest checkpoint")
    parser.add_argument("--title", default=None, help="(default: the maps and seeds)")


def run_plot(parser, args) -> int:
    """Draw the figure and print the tables (``skillchain plot``)."""
    labels = args.labels or [Path(p.split("+")[0]).name for p in args.runs]
    if len(labels) != len(args.runs):
        parser.error(f"{len(labels)} labels for {len(args.runs)} runs")
    try:
        loaded = [load_returns(p, args.partial) for p in args.runs]
        episodes = min(r.shape[1] for r, _ in loaded)
        windows = (default_windows(episodes) if args.windows is None
                   else parse_windows(args.windows))  # fmt: skip
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
