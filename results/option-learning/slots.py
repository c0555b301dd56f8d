"""Does the slot cap bind? Runs that differ only in ``--slots``, on the same seeds: options held
over time, how many agents fill their bank and when, and the returns paired by seed against the
first folder (the reference), with 95% intervals (Student's t quantile).

    python results/option-learning/slots.py REF OTHER [OTHER...]
    cd results/option-learning
    python slots.py screen-hard/end-outside-learned pilot-hard/end-outside-k48 screen-hard/flat

A flat run may be among them (it holds no options). Folders may hold more runs than others (a
20-run screen beside a 10-run pilot): the first ``min(runs)`` agents are compared, which share
seeds because every folder starts at its ``config.json`` ``seed`` (checked).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from compare import WINDOWS  # this folder's script, on the path when run as a script
from compare import fmt as interval

from skillchain_torch.trainers.study.intervals import mean_ci


def fmt(mean: float, half: float) -> str:
    return interval(mean, half) + (" *" if abs(mean) > half else "")


def main(folders: list[str]) -> None:
    runs = {}
    for f in folders:
        config = json.loads((Path(f) / "config.json").read_text())
        held = Path(f) / "n_options.npy"  # flat runs hold none
        runs[f] = (config, np.load(f"{f}/returns.npy"), np.load(held) if held.exists() else None)
    seeds = {c["seed"] for c, _, _ in runs.values()}
    if len(seeds) != 1:
        sys.exit(f"slots.py: the folders start at different seeds {sorted(seeds)}")
    n = min(r.shape[0] for _, r, _ in runs.values())
    episodes = min(r.shape[1] for _, r, _ in runs.values())
    print(f"{n} agents (seeds {seeds.pop()}+), {episodes} episodes\n")
    print("| run | slots | options at the end (median, max) | agents that fill the bank |"
          " median episode it fills |\n|---|---:|---|---:|---:|")
    for f, (config, _, held) in runs.items():
        if held is None:
            continue
        held = held[:n, :episodes]
        slots = config["slots"]
        full = held.max(1) >= slots
        first = [int(np.argmax(h >= slots)) + 1 for h in held[full]]
        when = f"{np.median(first):.0f}" if first else "-"
        print(f"| `{f}` | {slots} | {np.median(held[:, -1]):.0f}, {held[:, -1].max()} |"
              f" {int(full.sum())}/{n} | {when} |")
    ref = folders[0]
    windows = [(a, b) for a, b in WINDOWS if b <= episodes]
    print(f"\nReturns paired by seed against `{ref}` (`*`: the interval excludes 0)\n")
    print("| run | " + " | ".join(f"{a}-{b}" for a, b in windows) + " |")
    print("|---|" + "---|" * len(windows))
    base = runs[ref][1][:n]
    for f, (_, returns, _) in runs.items():
        if f == ref:
            cells = [f"{np.mean(base[:, a - 1:b]):,.0f}" for a, b in windows]
        else:
            cells = [fmt(*mean_ci(returns[:n, a - 1:b].mean(1) - base[:, a - 1:b].mean(1)))
                     for a, b in windows]
        print(f"| `{f}` | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1:])
