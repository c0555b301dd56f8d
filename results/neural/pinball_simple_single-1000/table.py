"""Pinball's neural runs (seeds 1000-1009) against the paper study's first 10 agents of the
same seeds (``results/paper/simple``: flat and the default's skill chaining, agents 0-9 are
seeds 1000-1009 by the seed contract), and the paper preset's linear skill chaining on those
seeds (``results/option-learning/confirm/paper-k48``, agents 0-9, episodes 1-50).
Prints the README's table; 95% Student-t intervals over runs, Welch for differences. (The
README's table was made from ``results/paper-v3/simple``, in git at 6835785, restorable with
``git archive 6835785 results/paper-v3 | tar -x``: the same flat runs, and the then default's
skill chaining, so its "sc-linear (default)" row differs from what this prints.)

    python results/neural/pinball_simple_single-1000/table.py
"""

from pathlib import Path

import numpy as np

from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci

HERE = Path(__file__).resolve().parent
PAPER = HERE.parents[1] / "paper" / "simple"
WINDOWS = [(1, 10), (11, 20), (21, 30), (31, 40), (41, 50)]
NEURAL = ("flat-neural-50", "sc-neural-50", "sc-neural-options-50")
# each neural skill-chaining run against the run it is compared with
PAIRS = (("sc-neural-50", "flat-neural-50"), ("flat-neural-50", "flat (linear)"),
         ("sc-neural-options-50", "flat (linear)"),
         ("sc-neural-options-50", "sc-linear (paper preset)"))


def runs() -> dict[str, dict[str, np.ndarray]]:
    out = {"flat (linear)": {"returns": np.load(PAPER / "flat" / "returns.npy")[:10]},
           "sc-linear (default)": {
               "returns": np.load(PAPER / "skill-chaining" / "returns.npy")[:10]}}
    # the paper preset's linear skill chaining, same seeds (48 slots; at most 6 used by 50)
    paper = HERE.parents[1] / "option-learning" / "confirm" / "paper-k48"
    out["sc-linear (paper preset)"] = {k: np.load(paper / f"{k}.npy")[:10, :50] for k in
                                       ("returns", "n_options", "option_outcomes")}
    for name in NEURAL:
        folder = HERE / name
        if (folder / "returns.npy").exists():
            out[name] = {k: np.load(folder / f"{k}.npy") for k in ("returns", "n_options",
                                                                   "option_outcomes")}
    return out


def main() -> None:
    data = runs()
    print("| variant | " + " | ".join(f"{a}-{b}" for a, b in WINDOWS) + " | options at the end "
          "| executions, last 10 episodes: success / timeout |")
    print("|---|" + "---|" * (len(WINDOWS) + 2))
    for name, r in data.items():
        ret = r["returns"]
        cells = ["{:,.0f} ± {:,.0f}".format(*mean_ci(ret[:, a - 1:b].mean(1)))
                 if b <= ret.shape[1] else "" for a, b in WINDOWS]
        opts = execs = ""
        if "n_options" in r and r["n_options"][:, -1].max() > 0:
            opts = f"{r['n_options'][:, -1].mean():.1f} (max {r['n_options'][:, -1].max()})"
            o = r["option_outcomes"][:, -10:].sum((0, 1))
            n = int(o.sum())
            execs = f"{o[0] / n:.2f} / {o[1] / n:.2f} (n = {n:,})" if n else "none"
        print(f"| {name} | " + " | ".join(cells) + f" | {opts} | {execs} |")
    for one, other in PAIRS:
        if one not in data or other not in data:
            continue
        a, b = data[one]["returns"], data[other]["returns"]
        e = min(a.shape[1], b.shape[1])
        cells = [fmt_diff(a[:, lo - 1:hi].mean(1), b[:, lo - 1:hi].mean(1))
                 for lo, hi in WINDOWS if hi <= e]
        print(f"{one} - {other}: " + ", ".join(f"{lo}-{hi} {c}" for (lo, hi), c in
                                               zip(WINDOWS, cells)))


def fmt_diff(a: np.ndarray, b: np.ndarray) -> str:
    m, h = diff_ci(a, b)
    return f"{m:+,.0f} ± {h:,.0f}"


if __name__ == "__main__":
    main()
