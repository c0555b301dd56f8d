"""Tables and figures of the Gymnasium study (issue 29): flat Sarsa, skill chaining and given
options on MountainCar-v0 and Acrobot-v1, 10 runs each.

    python results/gym/report.py            # reads results/gym/<env>/<agent>/returns.npy

Intervals use Student's t quantile (10 runs: 2.262 for a mean; Welch-Satterthwaite degrees of
freedom for a difference). Writes results/gym/tables.md and results/gym/<env>.png.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
AGENTS = ("flat", "skill-chaining", "skill-chaining-paper", "given-options")
WINDOWS = ((1, 10), (11, 25), (26, 50), (51, 100))
# Two-sided 95% t quantiles by degrees of freedom (1..30, then the normal's).
_T95 = (12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179,
        2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064,
        2.060, 2.056, 2.052, 2.048, 2.045, 2.042)


def t95(df: float) -> float:
    """The two-sided 95% quantile of Student's t with ``df`` degrees of freedom (linear
    between whole degrees, 1.96 beyond 30)."""
    if df >= 30:
        return 1.96 if df > 120 else 2.042 - (df - 30) * (2.042 - 1.96) / 90
    lo = max(1, int(math.floor(df)))
    hi = min(30, lo + 1)
    w = df - lo
    return (1 - w) * _T95[lo - 1] + w * _T95[hi - 1]


def mean_ci(x: np.ndarray) -> tuple[float, float]:
    n = len(x)
    return float(x.mean()), t95(n - 1) * float(x.std(ddof=1)) / math.sqrt(n)


def diff_ci(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    va, vb = a.var(ddof=1) / len(a), b.var(ddof=1) / len(b)
    df = (va + vb) ** 2 / (va**2 / (len(a) - 1) + vb**2 / (len(b) - 1)) if va + vb > 0 else 1e9
    return float(a.mean() - b.mean()), t95(df) * math.sqrt(va + vb)


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
        half = t95(n - 1) * smooth.std(0, ddof=1) / math.sqrt(n)
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
