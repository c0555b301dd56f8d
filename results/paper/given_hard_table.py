"""The hard given-options arm at 48 slots against flat, its own discoverers and the 12-slot
trees' given options: mean return per episode window, 95% t intervals over runs (``*``:
excludes 0).

Reads the stacked arm (``hard/given-options``) where it holds 100 agents, else the finished
slices that follow on from agent 0 (``hard/given-slices``), and pairs agent p with discoverer
p (``hard/skill-chaining``) and with the 12-slot study's given agent p
(``results/paper-k12/hard/given-options``); flat (``hard/flat``) is compared by Welch.

    python results/paper/given_hard_table.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))
from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci  # noqa: E402

HARD = HERE / "hard"
K12 = HERE.parent / "paper-k12" / "hard" / "given-options"
WINDOWS = ((1, 10), (11, 25), (26, 50), (51, 100), (101, 150), (151, 200), (201, 250))


def given_returns() -> np.ndarray:
    """The arm's returns, agents 0..n-1: the stacked arm, else the slices from agent 0 on."""
    arm = HARD / "given-options" / "returns.npy"
    if arm.is_file():
        return np.load(arm)
    spans = sorted(tuple(int(x) for x in d.name.split("-"))
                   for d in (HARD / "given-slices").glob("*-*") if (d / "run_info.json").is_file())
    rows, end = [], 0
    for a, b in spans:
        if a != end:
            break  # a gap: agents from here on are not paired in order
        rows.append(np.load(HARD / "given-slices" / f"{a}-{b}" / "returns.npy"))
        end = b
    if not rows:
        sys.exit(f"{HARD}/given-slices holds no slice from agent 0")
    return np.concatenate(rows)


def cell(mean: float, half: float) -> str:
    return f"{mean:+,.0f} ± {half:,.0f}" + (" *" if abs(mean) > half else "")


def main() -> None:
    given = given_returns()
    n = given.shape[0]
    own = np.load(HARD / "skill-chaining" / "returns.npy")[:n]
    flat = np.load(HARD / "flat" / "returns.npy")
    k12 = np.load(K12 / "returns.npy")[:n]
    w = lambda r, a, b: r[:, a - 1:b].mean(1)  # noqa: E731  (a run's mean over a window)
    print(f"{n} given agents (seeds 1000-{999 + n}), {given.shape[1]} episodes\n")
    print("| episodes | given options, 48-slot trees | - flat (Welch) | - their discoverers "
          "(paired) | - 12-slot trees' given options (paired) |\n|---|---:|---|---|---|")
    for a, b in WINDOWS:
        g = w(given, a, b)
        print(f"| {a}-{b} | {cell(*mean_ci(g))} | {cell(*diff_ci(g, w(flat, a, b)))} | "
              f"{cell(*mean_ci(g - w(own, a, b)))} | {cell(*mean_ci(g - w(k12, a, b)))} |")
    d_welch = diff_ci(w(given, 201, 250), w(own, 201, 250))
    print(f"\ngiven - discoverers over 201-250, Welch (the report's test): {cell(*d_welch)}")


if __name__ == "__main__":
    main()
