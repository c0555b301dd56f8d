"""Window means (± 95%) and long-episode counts of run directories, as a markdown table.

    python results/runaway/screen_table.py results/runaway/screen/*
"""
import sys
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.study.intervals import mean_ci
from skillchain_torch.trainers.study.paper_report import WINDOWS, window

heads = [f"{a}-{b}" for a, b in WINDOWS]
heads += [">10k after 50", ">5k after 50", "longest after 50", "steps"]
print("| cell | runs | " + " | ".join(heads) + " |")
print("|---" * (len(heads) + 2) + "|")
for run in map(Path, sys.argv[1:]):
    if not (run / "returns.npy").exists():
        continue  # e.g. a diverged run keeps only partial arrays
    returns, lengths = np.load(run / "returns.npy"), np.load(run / "lengths.npy")
    cells = []
    for a, b in WINDOWS:
        cells.append("{:,.0f} ± {:,.0f}".format(*mean_ci(window(returns, a, b))))
    late = lengths[:, 50:]
    cells += [f"{(late > 10000).sum()}", f"{(late > 5000).sum()}", f"{late.max():,}",
              f"{lengths.sum() / 1e6:.1f}M"]
    print(f"| {run.name} | {len(returns)} | " + " | ".join(cells) + " |")
