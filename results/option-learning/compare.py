"""Issue 30's option-learning study: each variant's returns against flat Sarsa's, per window of
episodes, with 95% Welch intervals (Student's t quantile), each against the default (``frozen``)
paired by seed, options held, and how executions end.

    python results/option-learning/compare.py screen     # seeds 0-19 (screening only)
    python results/option-learning/compare.py confirm    # seeds 1000+ (the evidence)
    python results/option-learning/compare.py screen-hard   # any folder of variants

Reads ``<block>/<variant>/{returns,n_options,option_outcomes}.npy`` (``flat`` is the baseline)
and writes ``<block>/tables.md``, ``<block>/curves.png`` and, with the default's ``frozen`` in the
block, ``<block>/against_default.png`` (each variant minus the default per window, paired).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci, t_quantile

HERE = Path(__file__).resolve().parent

WINDOWS = ((1, 10), (11, 25), (26, 50), (51, 100), (101, 150), (151, 200), (201, 250))


def load(block: Path) -> dict[str, dict[str, np.ndarray]]:
    runs = {}
    for folder in sorted(p for p in block.iterdir() if (p / "returns.npy").exists()):
        runs[folder.name] = {name: np.load(folder / f"{name}.npy") for name in
                             ("returns", "n_options", "option_outcomes")
                             if (folder / f"{name}.npy").exists()}  # fmt: skip
    return runs


def fmt(mean: float, half: float) -> str:
    return f"{mean:+,.0f} ± {half:,.0f}"


def tables(runs: dict) -> list[str]:
    flat = runs.get("flat")
    episodes = min(r["returns"].shape[1] for r in runs.values())
    windows = [(a, b) for a, b in WINDOWS if b <= episodes]
    names = [n for n in runs if n != "flat"]
    lines = ["## Mean return per window (95% t interval over runs)", "",
             "| variant | runs | " + " | ".join(f"{a}-{b}" for a, b in windows) + " |",
             "|---|---|" + "---|" * len(windows)]  # fmt: skip
    for name, r in runs.items():
        cells = [fmt(*mean_ci(r["returns"][:, a - 1:b].mean(1))) for a, b in windows]
        lines.append(f"| {name} | {len(r['returns'])} | " + " | ".join(cells) + " |")
    if flat is not None:
        lines += ["", "## Variant - flat (95% Welch interval)", "",
                  "| variant | " + " | ".join(f"{a}-{b}" for a, b in windows) + " |",
                  "|---|" + "---|" * len(windows)]  # fmt: skip
        for name in names:
            cells = []
            for a, b in windows:
                d, h = diff_ci(runs[name]["returns"][:, a - 1:b].mean(1),
                               flat["returns"][:, a - 1:b].mean(1))  # fmt: skip
                star = "**" if abs(d) > h else ""
                cells.append(f"{star}{fmt(d, h)}{star}")
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
    base = runs.get("frozen")
    if base is not None:  # run i has seed first + i in every variant: paired by agent
        lines += ["", "## Variant - frozen (the default), paired by seed (95% t interval)", "",
                  "| variant | runs | " + " | ".join(f"{a}-{b}" for a, b in windows) + " |",
                  "|---|---|" + "---|" * len(windows)]  # fmt: skip
        for name in (n for n in names if n != "frozen"):
            x = runs[name]["returns"]
            n = min(len(x), len(base["returns"]))
            cells = []
            for a, b in windows:
                d, h = mean_ci(x[:n, a - 1:b].mean(1) - base["returns"][:n, a - 1:b].mean(1))
                star = "**" if abs(d) > h else ""
                cells.append(f"{star}{fmt(d, h)}{star}")
            lines.append(f"| {name} | {n} | " + " | ".join(cells) + " |")
    outcome_windows = list(dict.fromkeys(windows[2:4] + windows[-1:]))  # (each once)
    at = [e for e in dict.fromkeys((25, 50, episodes)) if e <= episodes]  # (short runs too)
    lines += ["", "## Options held, and how executions ended (all runs' executions in the "
              "window)", "", f"| variant | options at {' / '.join(map(str, at))} | max options | "
              + " | ".join(f"success / timeout {a}-{b}" for a, b in outcome_windows)
              + " |", "|---|---|---|" + "---|" * len(outcome_windows)]  # fmt: skip
    for name in names:
        r = runs[name]
        n = r.get("n_options")
        held, most = "-", "-"
        if n is not None:
            held = " / ".join(f"{n[:, e - 1].mean():.1f}" for e in at)
            most = f"{int(n.max())}"
        cells = []
        for a, b in outcome_windows:
            o = r.get("option_outcomes")
            if o is None:
                cells.append("-")
                continue
            total = o[:, a - 1:b].sum((0, 1))
            ended = total.sum()
            cells.append(f"{total[0] / ended:.2f} / {total[1] / ended:.2f} (n={ended:,})"
                         if ended else "no executions")
        lines.append(f"| {name} | {held} | {most} | " + " | ".join(cells) + " |")
    return lines


def figure(runs: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    ax.set_prop_cycle(color=plt.cm.tab20(np.linspace(0, 1, 20))[: max(len(runs), 1)])
    for name, r in runs.items():
        x = r["returns"]
        kernel = np.ones(10) / 10  # a 10-episode moving average, per run
        smooth = np.array([np.convolve(row, kernel, mode="valid") for row in x])
        m = smooth.mean(0)
        h = t_quantile(0.975, len(smooth) - 1) * smooth.std(0, ddof=1) / np.sqrt(len(smooth))
        e = np.arange(10, x.shape[1] + 1)
        ax.plot(e, m, label=f"{name} ({len(x)} runs)")
        ax.fill_between(e, m - h, m + h, alpha=0.2)
    ax.set_xlabel("episode")
    ax.set_ylabel("return (10-episode moving average, 95% t band)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def paired_figure(runs: dict, path: Path, base: str = "frozen") -> None:
    """Each variant minus ``base`` per window, paired by seed, with its 95% t interval: where
    a variant gains or loses against the default, in one glance."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    episodes = min(r["returns"].shape[1] for r in runs.values())
    windows = [(a, b) for a, b in WINDOWS if b <= episodes]
    names = [n for n in runs if n != base]
    fig, ax = plt.subplots(figsize=(9, 4.5))
    width = 0.8 / max(len(names), 1)
    colors = plt.cm.tab20(np.linspace(0, 1, 20))
    for i, name in enumerate(names):
        x, y = runs[name]["returns"], runs[base]["returns"]
        n = min(len(x), len(y))
        cis = [mean_ci(x[:n, a - 1:b].mean(1) - y[:n, a - 1:b].mean(1)) for a, b in windows]
        pos = np.arange(len(windows)) - 0.4 + (i + 0.5) * width
        ax.errorbar(pos, [m for m, _ in cis], yerr=[h for _, h in cis], fmt="o", ms=3,
                    capsize=2, color=colors[i % 20], label=f"{name} ({n} runs)")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xticks(range(len(windows)), [f"{a}-{b}" for a, b in windows])
    ax.set_xlabel("episodes")
    ax.set_ylabel(f"return - {base} (paired by seed, 95% t)")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main() -> None:
    block = HERE / (sys.argv[1] if len(sys.argv) > 1 else "screen")
    runs = load(block)
    lines = [f"# {block.name}: each variant against flat", "", *tables(runs), ""]
    (block / "tables.md").write_text("\n".join(lines))
    figure(runs, block / "curves.png")
    if "frozen" in runs:
        paired_figure(runs, block / "against_default.png")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
