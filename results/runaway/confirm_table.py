"""Confirmation on seeds 1000-1029: the paper study's first 30 agents (order 4) against order 5.

The order-4 study is the one the order-5 runs were made against: ``results/paper-v3`` in git at
6835785 (removed from the tree), restorable with ``git archive 6835785 results/paper-v3 | tar -x``.

    python results/runaway/confirm_table.py results/paper-v3
"""
import argparse

import numpy as np

from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci
from skillchain_torch.trainers.study.paper_report import WINDOWS, window

parser = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
parser.add_argument("study", help="the order-4 study's folder (its simple/<agent> folders)")
study = parser.parse_args().study
RUNS = {"flat o4": f"{study}/simple/flat",
        "sc o4": f"{study}/simple/skill-chaining",
        "flat o5": "results/runaway/confirm/flat-o5",
        "sc o5": "results/runaway/confirm/sc-o5"}
PAIRS = [("sc o4", "flat o4"), ("sc o5", "flat o5"), ("flat o5", "flat o4"), ("sc o5", "sc o4")]


def welch(a, b):
    d, h = diff_ci(a, b)
    return f"{d:+,.0f} ± {h:,.0f}" + (" *" if abs(d) > h else "")


def fmt(x):
    return "{:,.0f} ± {:,.0f}".format(*mean_ci(x))


returns = {k: np.load(f"{v}/returns.npy")[:30] for k, v in RUNS.items()}
lengths = {k: np.load(f"{v}/lengths.npy")[:30] for k, v in RUNS.items()}
heads = ["flat o4", "skill chaining o4", "flat o5", "skill chaining o5"]
heads += [f"{a} - {b}".replace("sc", "skill chaining") for a, b in PAIRS]
print("| episodes | " + " | ".join(heads) + " |")
print("|---" * (len(heads) + 1) + "|")
for a, b in WINDOWS:
    m = {k: window(r, a, b) for k, r in returns.items()}
    cells = [fmt(m[k]) for k in RUNS] + [welch(m[x], m[y]) for x, y in PAIRS]
    print(f"| {a}-{b} | " + " | ".join(cells) + " |")
print()
print("| run | over 10,000 steps after episode 50 | over 5,000 | longest after 50 | agent steps |")
print("|---|---|---|---|---|")
for k, steps in lengths.items():
    late = steps[:, 50:]
    print(f"| {k} | {(late > 10000).sum()} | {(late > 5000).sum()} | {late.max():,} | "
          f"{steps.sum() / 1e6:.1f} M |")
