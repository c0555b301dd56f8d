"""Issue 31's pilots: curves and tables per environment, and the initiation sets of the options.

    python results/neural/figures.py          # every environment folder here

For each ``<env>/`` with finished variants: ``tables.md`` and ``curves.png`` (each variant
against ``flat``, 95% Student-t intervals, through ``results/option-learning/compare.py``), and
for each skill-chaining variant ``<variant>/initiation_sets.png``: the options of the agent
holding the most, each set
drawn over the states that agent visited (the examples its classifier stored), on the first two
observation dims (in the unit box: MountainCar's position and velocity, Acrobot's cos and sin
of the first joint, Pinball's x and y). ``option_trajectory.png`` (one greedy episode
coloured by the option in control) is written by ``skillchain train`` itself.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def compare_module():
    path = HERE.parent / "option-learning" / "compare.py"
    spec = importlib.util.spec_from_file_location("compare", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def initiation_sets(run: Path, agent: int | None = None, limit: int = 8, dims=(0, 1)) -> None:
    """An agent's options' sets over states it visited: every example its classifier stored
    (any slot: real states), coloured where the option's set holds it (default: the agent
    holding the most options, then the most stored states)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import torch

    from skillchain_torch.options import OptionBank

    bank = OptionBank.load(run / "options.pt")
    clf = bank.classifier
    if agent is None:  # most options, then most stored states
        agent = int((bank.live().sum(-1) * 10**6 + clf.count.sum(-1)).argmax())
    slots = bank.live()[agent].nonzero().flatten().tolist()[:limit]
    stored = torch.arange(clf.examples.shape[2])[None, :] < clf.count[agent][:, None]  # [K, C]
    points = clf.examples[agent][stored]  # [N, D]: states this agent visited
    if not slots or len(points) == 0:
        return
    i, j = dims
    fig, axes = plt.subplots(1, len(slots), figsize=(max(2.6 * len(slots), 7.5), 2.8),
                             squeeze=False)  # (wide enough for the title)
    for ax, k in zip(axes[0], slots):
        inside = clf.contains_points(agent, k, points).numpy()
        xy = points.numpy()
        ax.scatter(xy[~inside, i], xy[~inside, j], s=2, c="0.8", rasterized=True)
        ax.scatter(xy[inside, i], xy[inside, j], s=2, c="tab:red", rasterized=True)
        ax.set_xlim(0, 1), ax.set_ylim(0, 1)
        ax.set_title(f"option {k}: {inside.mean():.0%} inside", fontsize=9)
        ax.set_xlabel(f"obs dim {i}")
        ax.set_ylabel(f"obs dim {j}")
    fig.suptitle(f"{run.parent.name} {run.name}, agent {agent}: initiation sets (red) over "
                 f"{len(points):,} visited states ({type(clf).__name__})", fontsize=10)  # fmt: skip
    fig.tight_layout()
    fig.savefig(run / "initiation_sets.png", dpi=110)
    plt.close(fig)


def main() -> None:
    compare = compare_module()
    for env in sorted(p for p in HERE.iterdir() if p.is_dir()):
        runs = compare.load(env)
        if not runs:
            continue
        lines = [f"# {env.name}: each variant against flat", "", *compare.tables(runs), ""]
        (env / "tables.md").write_text("\n".join(lines))
        compare.figure(runs, env / "curves.png")
        for name in runs:
            if (env / name / "options.pt").exists() and np.load(
                    env / name / "n_options.npy").max() > 0:  # fmt: skip
                initiation_sets(env / name)
        print("\n".join(lines))


if __name__ == "__main__":
    main()
