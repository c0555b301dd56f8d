"""Window table of runs against flat on the same seeds (issue 52's screening pilots).

    python results/faithful/table.py results/faithful/screen-simple-10x250

Each cell is the mean over runs of each run's window mean, with a 95% t interval; the second
column of each window is the arm minus flat with a Welch 95% interval (``*``: excludes 0).
Every arm's ``returns.npy`` (runs x episodes) and the ``flat`` arm's sit in sub-folders.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci

WINDOWS = ((1, 10), (26, 50), (51, 100), (101, 150), (151, 200), (201, 250))


def window(returns: np.ndarray, first: int, last: int) -> np.ndarray:
    return returns[:, first - 1:last].mean(axis=1)


def table(folder: Path) -> str:
    arms = sorted(p.parent.name for p in folder.glob("*/returns.npy"))
    flat = np.load(folder / "flat" / "returns.npy")
    episodes = min(np.load(folder / a / "returns.npy").shape[1] for a in arms)
    windows = [w for w in WINDOWS if w[1] <= episodes]
    head = "| arm | runs | options (end) | " + " | ".join(f"{a}-{b}" for a, b in windows) + " |"
    lines = [head, "|---|---:|---:|" + "---:|" * len(windows)]
    for arm in ["flat"] + [a for a in arms if a != "flat"]:
        r = np.load(folder / arm / "returns.npy")
        n_opt = folder / arm / "n_options.npy"
        opts = f"{np.load(n_opt)[:, -1].mean():.1f}" if n_opt.exists() else "-"
        cells = []
        for a, b in windows:
            m, h = mean_ci(window(r, a, b))
            cell = f"{m:,.0f} ± {h:,.0f}"
            if arm != "flat":
                d, dh = diff_ci(window(r, a, b), window(flat, a, b))
                star = " *" if abs(d) > dh else ""
                cell += f"<br>{d:+,.0f} ± {dh:,.0f}{star}"
            cells.append(cell)
        lines.append(f"| {arm} | {r.shape[0]} | {opts} | " + " | ".join(cells) + " |")
    seeds = json.loads((folder / "flat" / "config.json").read_text()).get("seed")
    return f"seed block from {seeds}, {episodes} episodes\n\n" + "\n".join(lines)


def runaway(folder: Path, after: int = 50, long: int = 20_000) -> str:
    """Cost and runaway per arm: the whole command's wall time, agent steps, agents with an
    episode over ``long`` steps after episode ``after``, the longest episode, and executions
    per agent-episode after ``after`` that succeeded or timed out (``option_outcomes.npy``)."""
    lines = ["| arm | whole command (s) | agent steps | agents with an episode over "
             f"{long:,} steps after episode {after} | longest episode | executions per "
             f"agent-episode after {after}: success, timeout |", "|---|---:|---:|---:|---:|---|"]
    for arm in sorted(p.parent.name for p in folder.glob("*/lengths.npy")):
        lengths = np.load(folder / arm / "lengths.npy")
        info = json.loads((folder / arm / "run_info.json").read_text())
        runaway_agents = int((lengths[:, after:] > long).any(axis=1).sum())
        outcomes = folder / arm / "option_outcomes.npy"
        if outcomes.exists():
            late = np.load(outcomes)[:, after:].mean(axis=(0, 1))
            executions = f"{late[0]:.2f}, {late[1]:.2f}"
        else:
            executions = "-"
        lines.append(f"| {arm} | {info.get('wall_time_s', float('nan')):,.0f} | "
                     f"{lengths.sum() / 1e6:.1f} M | {runaway_agents} | {lengths.max():,} | "
                     f"{executions} |")
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--runaway", action="store_true",
                        help="also the cost and runaway table")
    args = parser.parse_args(argv)
    print(table(args.folder))
    if args.runaway:
        print()
        print(runaway(args.folder))


if __name__ == "__main__":
    main()
