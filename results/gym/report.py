"""Tables and figures of the Gymnasium study (issue 29): flat Sarsa, skill chaining and given
options on MountainCar-v0 and Acrobot-v1, 10 runs each.

    python results/gym/report.py            # reads results/gym/<env>/<agent>/returns.npy

Intervals are Student's t (``skillchain_torch.trainers.study.intervals``; 10 runs: 2.262
standard errors for a mean; Welch-Satterthwaite degrees of freedom for a difference). Writes
results/gym/tables.md and results/gym/<env>.png.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci, t_quantile

HERE = Path(__file__).resolve().parent
AGENTS = ("flat", "skill-chaining", "skill-chaining-paper", "given-options")
WINDOWS = ((1, 10), (11, 25), (26, 50), (51, 100))


def load(env: str) -> dict[str, dict[str, np.ndarray]]:
    out = {}
    for agent in AGENTS:
        folder = HERE / env / agent
        if (folder / "returns.npy").exists():
            out[agent] = {name: np.load(folder / f"{name}.npy") for name in
                          ("returns", "lengths", "n_options") if (folder / f"{name}.npy").exists()}
    return out


def table(env: str, runs: dict) -> list[str]:
    lines = [f"### {env}", "", "| episodes | " + " | ".join(runs) + " | "
             + " | ".join(f"{a} - flat" for a in runs if a != "flat") + " |",
             "|---" * (2 * len(runs)) + "|"]
    for first, last in WINDOWS:
        cells = []
        means = {a: r["returns"][:, first - 1:last].mean(1) for a, r in runs.items()}
        for agent in runs:
            m, h = mean_ci(means[agent])
            cells.append(f"{m:,.1f} ± {h:,.1f}")
        for other in ("skill-chaining", "skill-chaining-paper", "given-options"):
            if other in means and "flat" in means:
                d, h = diff_ci(means[other], means["flat"])
                star = " *" if abs(d) > h else ""
                cells.append(f"{d:+,.1f} ± {h:,.1f}{star}")
        lines.append(f"| {first}-{last} | " + " | ".join(cells) + " |")
    for agent, r in runs.items():
        if "n_options" in r:
            final = r["n_options"][:, -1]
            m, h = mean_ci(final.astype(float))
            lines.append(f"\n{agent}: options held at the last episode {m:.1f} ± {h:.1f} "
                         f"(min {final.min()}, max {final.max()})")
    return lines + [""]


def figure(env: str, runs: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for agent, r in runs.items():
        ret = r["returns"]
        n, episodes = ret.shape
        smooth = np.stack([np.convolve(row, np.ones(5) / 5, mode="valid") for row in ret])
        mean = smooth.mean(0)
        half = t_quantile(0.975, n - 1) * smooth.std(0, ddof=1) / math.sqrt(n)
        x = np.arange(5, episodes + 1)
        ax.plot(x, mean, label=f"{agent} ({n} runs)")
        ax.fill_between(x, mean - half, mean + half, alpha=0.25)
    ax.set_xlabel("episode (5-episode moving mean)")
    ax.set_ylabel("return")
    ax.set_title(f"{env}: mean and 95% t interval over runs")
    ax.legend()
    fig.tight_layout()
    fig.savefig(HERE / f"{env}.png", dpi=120)
    plt.close(fig)


def main() -> None:
    md = ["# Tables (written by report.py)", ""]
    for env in ("MountainCar-v0", "Acrobot-v1"):
        runs = load(env)
        if runs:
            md += table(env, runs)
            figure(env, runs)
    (HERE / "tables.md").write_text("\n".join(md) + "\n")
    print("\n".join(md))


if __name__ == "__main__":
    main()
