"""The hard given-options arm at 48 slots against flat, its own discoverers and the 12-slot
trees' given options: mean return per episode window, 95% t intervals over runs (``*``:
excludes 0).

Reads the stacked arm (``hard/given-options``) where it exists, else the finished slices that
follow on from agent 0 (``hard/given-slices``, found as ``given_hard_slices.py`` finds them),
and pairs agent p with discoverer p (``hard/skill-chaining``) and with the 12-slot study's
given agent p (``results/paper-k12/hard/given-options``); flat (``hard/flat``) is compared by
Welch. Windows and number format are the report's.

    python results/paper/given_hard_table.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import given_hard_slices as slices  # this folder's slice script (run as a script: on sys.path)
import numpy as np

from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci
from skillchain_torch.trainers.study.paper_report import WINDOWS, _fmt_diff, window

HERE = Path(__file__).resolve().parent
K12 = HERE.parent / "paper-k12" / "hard" / "given-options"


def given_returns() -> np.ndarray:
    """The arm's returns, agents 0..n-1: the stacked arm, else the slices from agent 0 on."""
    arm = slices.ARM / "returns.npy"
    if arm.is_file():
        return np.load(arm)
    rows, end = [], 0
    for a, b in slices._slices():
        if a != end:
            break  # a gap: agents from here on would not pair with their seeds
        rows.append(np.load(slices.SLICES / f"{a}-{b}" / "returns.npy"))
        end = b
    if not rows:
        sys.exit(f"{slices.SLICES} holds no slice from agent 0")
    return np.concatenate(rows)


def main() -> None:
    given = given_returns()
    n = given.shape[0]
    own = np.load(slices.DISCOVERERS / "returns.npy")[:n]
    flat = np.load(HERE / "hard" / "flat" / "returns.npy")
    k12 = np.load(K12 / "returns.npy")[:n]
    print(f"{n} given agents (seeds 1000-{999 + n}), {given.shape[1]} episodes\n")
    print("| episodes | given options, 48-slot trees | - flat (Welch) | - their discoverers "
          "(paired) | - 12-slot trees' given options (paired) |\n|---|---:|---|---|---|")
    for a, b in WINDOWS:
        g = window(given, a, b)
        print(f"| {a}-{b} | {_fmt_diff(*mean_ci(g))} | {_fmt_diff(*diff_ci(g, window(flat, a, b)))}"
              f" | {_fmt_diff(*mean_ci(g - window(own, a, b)))}"
              f" | {_fmt_diff(*mean_ci(g - window(k12, a, b)))} |")
    d_welch = diff_ci(window(given, 201, 250), window(own, 201, 250))
    print(f"\ngiven - discoverers over 201-250, Welch (the report's test): {_fmt_diff(*d_welch)}")


if __name__ == "__main__":
    main()
