"""Window means (± 95%) and long-episode counts of run directories, as a markdown table.

    python results/runaway/screen_table.py results/runaway/screen/*
"""
import sys
from pathlib import Path

import numpy as np

WINDOWS = [(1, 10), (11, 25), (26, 50), (51, 100), (101, 150), (151, 200), (201, 250)]


def half_width(x):
    return 1.96 * x.std(ddof=1) / np.sqrt(len(x))


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
        m = returns[:, a - 1:b].mean(1)
        cells.append(f"{m.mean():,.0f} ± {half_width(m):,.0f}")
    late = lengths[:, 50:]
    cells += [f"{(late > 10000).sum()}", f"{(late > 5000).sum()}", f"{late.max():,}",
              f"{lengths.sum() / 1e6:.1f}M"]
    print(f"| {run.name} | {len(returns)} | " + " | ".join(cells) + " |")
