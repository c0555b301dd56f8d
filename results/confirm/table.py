"""Issue 52's confirmation block: the tables and the confirmatory tests, with Holm's correction.

    python results/confirm/table.py results/confirm/simple-5000x100
    python results/confirm/table.py results/confirm/hard-5000x100 --instance hard

Every arm of ``run.sh`` (``run_hard.sh``) on seeds 5000-5099 (100 x 250; on the hard instance
the controls (a) and (b) at 50, seeds 5000-5049). Each instance's confirmatory family was fixed
here before its block ran (the simple family in 72c3f2c; the hard family in the commit that
added ``HARD_CONFIRMATORY``, before any hard arm but flat's first 25 agents had finished):
each claim is "ahead", a one-sided Welch t test of the arm's mean over the window above the
other arm's, and Holm's step-down correction holds the family-wise error at 5% over all of
them. "Not behind" claims are read from Welch's two-sided 95% interval (it must not lie wholly
below 0) and are descriptive, as are every other window and arm of the tables.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.study.intervals import _t_upper, diff_ci, mean_ci, welch_df

WINDOWS = ((1, 10), (26, 50), (51, 100), (101, 150), (151, 200), (201, 250))
# (claim, arm, against, window): "arm is ahead of against over window", one-sided.
CONFIRMATORY = (
    ("the default is ahead of flat early", "default", "flat", (26, 50)),
    ("the faithful reading is ahead of flat early", "paper-b2", "flat", (26, 50)),
    ("the paper preset is ahead of flat early", "paper", "flat", (26, 50)),
    ("skill chaining beats no chaining (a)", "default", "no-chaining", (26, 50)),
    ("skill chaining beats random subgoals (b)", "default", "random-subgoals", (26, 50)),
    ("skill chaining beats a richer flat agent, order 5 (c)", "default", "flat-o5", (26, 50)),
    ("skill chaining beats a richer flat agent, order 6 (c)", "default", "flat-o6", (26, 50)),
    ("given options start ahead of flat", "given-options", "flat", (1, 10)),
)
# The hard instance's family (issue 52: its richer flat agent is order 6 only, order 5 being
# the hard baseline). An arm not yet complete enters Holm's correction with p = 1: the family's
# size is fixed, whatever has run.
HARD_CONFIRMATORY = (
    ("the default is ahead of flat early", "default", "flat", (26, 50)),
    ("the faithful reading is ahead of flat early", "paper-b2", "flat", (26, 50)),
    ("the paper preset is ahead of flat early", "paper", "flat", (26, 50)),
    ("skill chaining beats no chaining (a)", "default", "no-chaining", (26, 50)),
    ("skill chaining beats random subgoals (b)", "default", "random-subgoals", (26, 50)),
    ("skill chaining beats a richer flat agent, order 6 (c)", "default", "flat-o6", (26, 50)),
    ("given options start ahead of flat", "given-options", "flat", (1, 10)),
)
# The runs each arm needs before its claims are tested (the hard controls (a), (b): 50).
RUNS = {"simple": {}, "hard": {"no-chaining": 50, "random-subgoals": 50}}
# Descriptive "not behind" readings at the end (two-sided 95% intervals).
NOT_BEHIND = (("default", "flat"), ("paper-b2", "flat"), ("paper", "flat"),
              ("default", "flat-o5"), ("default", "flat-o6"), ("given-options", "default"))


def window(returns: np.ndarray, first: int, last: int) -> np.ndarray:
    return returns[:, first - 1:last].mean(axis=1)


def welch_p_greater(x, y) -> tuple[float, float]:
    """``(t, one-sided p)`` of Welch's test that mean(x) > mean(y).

    Example:
        >>> t, p = welch_p_greater([1.0, 2.0, 3.0], [2.0, 3.0, 4.0])
        >>> round(t, 3), round(p, 3)   # behind: p well above 1/2
        (-1.225, 0.856)
    """
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    se = math.sqrt(x.var(ddof=1) / x.size + y.var(ddof=1) / y.size)
    t = (x.mean() - y.mean()) / se
    df = welch_df(x, y)
    # (_t_upper is P(T > t) for t >= 0: a negative t's p is the complement of |t|'s)
    p = _t_upper(t, df) if t >= 0 else 1.0 - _t_upper(-t, df)
    return float(t), float(p)


def holm(pvalues: list[float], alpha: float = 0.05) -> list[bool]:
    """Holm's step-down rejections, in the input order."""
    order = sorted(range(len(pvalues)), key=lambda i: pvalues[i])
    reject = [False] * len(pvalues)
    for rank, i in enumerate(order):
        if pvalues[i] > alpha / (len(pvalues) - rank):
            break
        reject[i] = True
    return reject


def load(folder: Path) -> dict[str, np.ndarray]:
    return {p.parent.name: np.load(p) for p in sorted(folder.glob("*/returns.npy"))}


def windows_table(arms: dict[str, np.ndarray]) -> str:
    flat = arms["flat"]
    head = "| arm | runs | " + " | ".join(f"{a}-{b}" for a, b in WINDOWS) + " |"
    lines = [head, "|---|---:|" + "---:|" * len(WINDOWS)]
    for name in ["flat"] + [a for a in arms if a != "flat"]:
        r, cells = arms[name], []
        for a, b in WINDOWS:
            m, h = mean_ci(window(r, a, b))
            cell = f"{m:,.0f} ± {h:,.0f}"
            if name != "flat":
                d, dh = diff_ci(window(r, a, b), window(flat, a, b))
                cell += f"<br>{d:+,.0f} ± {dh:,.0f}{' *' if abs(d) > dh else ''}"
            cells.append(cell)
        lines.append(f"| {name} | {r.shape[0]} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def complete(arms: dict[str, np.ndarray], arm: str, instance: str) -> bool:
    """The arm has run every agent its claims need."""
    return arm in arms and arms[arm].shape[0] >= RUNS[instance].get(arm, 100)


def confirmatory(arms: dict[str, np.ndarray], instance: str = "simple") -> str:
    family = HARD_CONFIRMATORY if instance == "hard" else CONFIRMATORY
    rows, pvalues = [], []
    for claim, arm, against, (a, b) in family:
        if not (complete(arms, arm, instance) and complete(arms, against, instance)):
            rows.append((claim, arm, against, (a, b), None))
            pvalues.append(1.0)  # not yet run: counts in the family, never rejected
            continue
        n = min(arms[arm].shape[0], arms[against].shape[0])  # (the controls' seeds 5000-5049)
        x, y = window(arms[arm][:n], a, b), window(arms[against][:n], a, b)
        d, dh = diff_ci(x, y)
        t, p = welch_p_greater(x, y)
        rows.append((claim, arm, against, (a, b), (d, dh, t, p)))
        pvalues.append(p)
    reject = iter(holm(pvalues))
    lines = ["| claim | arm - against, episodes | difference, Welch 95% | t | one-sided p | "
             "Holm (family of " f"{len(pvalues)}, 5%) |", "|---|---|---:|---:|---:|---|"]
    for claim, arm, against, (a, b), stats in rows:
        if stats is None:
            next(reject)
            have = ", ".join(f"{name} {arms[name].shape[0] if name in arms else 0} of "
                             f"{RUNS[instance].get(name, 100)}" for name in (arm, against))
            lines.append(f"| {claim} | {arm} - {against}, {a}-{b} | not yet run ({have}) "
                         "| | | |")
            continue
        d, dh, t, p = stats
        verdict = "confirmed" if next(reject) else "not confirmed"
        lines.append(f"| {claim} | {arm} - {against}, {a}-{b} | {d:+,.0f} ± {dh:,.0f} | "
                     f"{t:.2f} | {p:.2g} | {verdict} |")
    return "\n".join(lines)


def not_behind(arms: dict[str, np.ndarray], first: int = 201, last: int = 250) -> str:
    lines = [f"| arm - against, {first}-{last} | difference, Welch 95% | not behind |",
             "|---|---:|---|"]
    for arm, against in NOT_BEHIND:
        if arm not in arms or against not in arms:
            continue
        d, dh = diff_ci(window(arms[arm], first, last), window(arms[against], first, last))
        lines.append(f"| {arm} - {against} | {d:+,.0f} ± {dh:,.0f} | "
                     f"{'yes' if d + dh >= 0 else 'no: behind'} |")
    return "\n".join(lines)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path)
    parser.add_argument("--instance", choices=("simple", "hard"), default="simple",
                        help="which confirmatory family (default: simple)")
    args = parser.parse_args(argv)
    arms = load(args.folder)
    seeds = json.loads((args.folder / "flat" / "config.json").read_text()).get("seed")
    print(f"seed block from {seeds}; arms: {', '.join(arms)}\n")
    print(windows_table(arms))
    print("\nConfirmatory tests (one-sided Welch, Holm over the family):\n")
    print(confirmatory(arms, args.instance))
    print("\nAt the end, descriptive:\n")
    print(not_behind(arms))


if __name__ == "__main__":
    main()
