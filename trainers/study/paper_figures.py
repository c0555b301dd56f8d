"""The paper's figures from finished run directories (Figures 4-8).

* :func:`plot_curves` (Figures 4a and 6): mean return per episode of each agent kind with its
  95% interval over runs.
* :func:`solution_figure` (Figures 4b and 7): good greedy solutions of trained skill-chaining
  agents, coloured by the option in control, primitive actions in black (one per start state).
* :func:`initiation_figure` (Figures 5 and 8): for each option used in those solutions, its
  initiation-set density (lightness: the share of the 25 velocity pairs of {-1, -1/2, 0, 1/2,
  1} inside the set) with three sample trajectories of the option's own greedy policy started
  from states in its set.

The trained agents come from the run's final checkpoint (:func:`load_trained`).

Example:
    >>> import numpy as np, matplotlib; matplotlib.use("Agg")
    >>> ax = plot_curves({"flat": np.zeros((3, 5)), "skill chaining": np.ones((3, 5))})
    >>> len(ax.lines)
    2
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from skillchain_torch.trainers.outputs.option_trajectory import (
    OPTION_COLORS,
    _single_agent,
    greedy_trajectory,
)

__all__ = ["plot_curves", "load_trained", "trained_agents", "good_solutions", "solution_figure",
           "option_rollout", "initiation_figure", "AGENT_COLORS"]  # fmt: skip

AGENT_COLORS = {"flat": "tab:gray", "skill-chaining": "tab:blue", "given-options": "tab:red"}
LABELS = {"flat": "flat (no options)", "skill-chaining": "skill chaining",
          "given-options": "given options"}  # fmt: skip


def _save(fig, path, title: str, dpi: int) -> Path:
    import matplotlib.pyplot as plt

    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return Path(path)


def plot_curves(returns: dict, ax=None, title: str | None = None, smooth: int = 1):
    """Each ``returns[name] [runs, episodes]`` as a mean curve with a 95% band (mean +- t sd /
    sqrt(runs), Student's t), optionally averaged over ``smooth`` episodes."""
    from skillchain_torch.trainers.outputs.plots import learning_curve

    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(7.5, 4.5))
    for name, r in returns.items():
        mean, low, high = learning_curve(r)
        if smooth > 1:
            kernel = np.ones(smooth) / smooth
            mean, low, high = (np.convolve(v, kernel, mode="valid") for v in (mean, low, high))
        episodes = np.arange(1, mean.size + 1) + (smooth - 1) / 2
        color = AGENT_COLORS.get(name)
        ax.plot(episodes, mean, color=color, lw=1.5,
                label=f"{LABELS.get(name, name)} ({np.asarray(r).shape[0]} runs)")
        ax.fill_between(episodes, low, high, color=color, alpha=0.2, lw=0)
    ax.set_xlabel("episode")
    ax.set_ylabel("return")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    return ax


def load_trained(run_dir: str | Path):
    """The trainer of a finished run, restored from its last checkpoint (the trained agents).

    A given-options run's options path is read relative to the run's folders (as
    ``skillchain verify`` does); the checkpoint is loaded with that path in its config."""
    import dataclasses

    from skillchain_torch.trainers.config.config import TrainConfig
    from skillchain_torch.trainers.loop.population import PopulationTrainer
    from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint, read_checkpoint
    from skillchain_torch.trainers.study.verify import resolve_options_path

    run_dir = Path(run_dir)
    config = TrainConfig.load_json(run_dir / "config.json")
    if config.options:
        path = str(resolve_options_path(config.options, run_dir))
        config = dataclasses.replace(config, options=path)
    path = latest_checkpoint(run_dir)
    if path is None:
        raise ValueError(f"{run_dir}: no checkpoint to take the trained agents from")
    state = read_checkpoint(path)
    saved = state["config"]
    differ = saved.mismatches(dataclasses.replace(config, options=saved.options))
    if differ:
        raise ValueError(f"{path}: config fields {differ} differ from {run_dir}/config.json")
    trainer = PopulationTrainer(config)
    state["config"] = config.resolved().to_dict()
    trainer.load_state_dict(state)
    return trainer


def trained_agents(run_dir: str | Path):
    """``(trainer, first_agent)``: the trained agents of a run, and the run's index of the
    trainer's agent 0.

    A run sharded over Ray workers (``sharding.json``) keeps its checkpoints in its blocks, and
    one block's agents are one population: this takes the block whose agents hold the most
    options (the first on ties), so figures show ``first_agent + p`` for its agent ``p``.
    Any other run is :func:`load_trained` with ``first_agent`` 0.
    """
    import json

    from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint

    run_dir = Path(run_dir)
    sharding = run_dir / "sharding.json"
    if latest_checkpoint(run_dir) is not None or not sharding.is_file():
        return load_trained(run_dir), 0
    best = None
    for a, b in json.loads(sharding.read_text())["blocks"]:
        trainer = load_trained(run_dir / "blocks" / f"{a}-{b}")
        held = float(trainer.agent.bank.live().sum(-1).double().mean())
        if best is None or held > best[0]:
            best = (held, trainer, a)
    return best[1], best[2]


def good_solutions(agent, map_name: str, agents=None, seeds=range(12),
                   max_steps: int = 3000) -> list[dict]:  # fmt: skip
    """For each start state of the map, the best episode among ``agents`` (default all) that
    reaches the goal, preferring ones that use options; ``seeds`` pick the start. The first
    seed runs greedily, the others with the agent's training epsilon (a greedy policy often
    circles where one exploratory step frees it); the search stops once every start has a
    solution through options."""
    agents = range(agent.population) if agents is None else agents
    by_start: dict[tuple, dict] = {}
    for i, seed in enumerate(seeds):
        for p in agents:
            run = greedy_trajectory(agent, int(p), map_name, max_steps, seed=int(seed),
                                    epsilon=0.0 if i == 0 else agent.epsilon)
            start = tuple(np.round(run["states"][0, :2], 4))
            key = (run["terminated"], bool((run["options"] >= 0).any()), run["return"])
            best = by_start.get(start)
            if best is None or key > best[0]:
                by_start[start] = (key, run)
        if len(by_start) > 1 or "two" not in map_name:  # one start, or both seen
            if all(v[0][0] and v[0][1] for v in by_start.values()):
                break
    return [v[1] for _, v in sorted(by_start.items())]


def solution_figure(runs: list[dict], map_name: str, path: str | Path, title: str = "",
                    first_agent: int = 0) -> Path:  # fmt: skip
    """Figure 4b / 7: each greedy solution coloured by option (primitives black); agents are
    labelled ``first_agent + p`` (see :func:`trained_agents`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from skillchain_torch.trainers.outputs.option_trajectory import plot_option_trajectory

    fig, axes = plt.subplots(1, len(runs), figsize=(5 * len(runs), 5), squeeze=False)
    for ax, run in zip(axes[0], runs):
        plot_option_trajectory({**run, "agent": first_agent + run["agent"]}, map_name, ax=ax)
    return _save(fig, path, title, dpi=120)


@torch.no_grad()
def option_rollout(agent, p: int, slot: int, start_obs: torch.Tensor, map_name: str,
                   max_steps: int = 250) -> np.ndarray:  # fmt: skip
    """Raw states ``[T + 1, 4]`` of agent ``p``'s option ``slot`` run greedily by its own
    Q-head from observation ``start_obs [4]`` until its target fires, ``max_steps`` pass or
    the goal is reached."""
    from skillchain_torch.envs.pinball import load_map, pinball_step

    single = _single_agent(agent, p)
    pinball_map = load_map(map_name)
    obs = start_obs.to(torch.float64).reshape(1, 4)
    state = torch.cat([obs[:, :2], 2.0 * obs[:, 2:] - 1.0], dim=-1)
    states = [state[0].clone()]
    slot_t = torch.tensor([slot])
    for _ in range(max_steps):
        code = single.bank.q_head.encode(obs)
        q = single.bank.q_head.slot_values_rows(code, slot_t, torch.tensor([0]))
        action = q.argmax(-1)
        state, _, terminated = pinball_step(state, action, pinball_map)
        states.append(state[0].clone())
        obs = torch.cat([state[:, :2], (state[:, 2:] + 1.0) / 2.0], dim=-1)
        contains = single.membership(obs)
        reached = single.targets(obs, terminated.reshape(1), contains)[0, slot]
        if bool(reached) or bool(terminated.any()):
            break
    return torch.stack(states).numpy()


def initiation_figure(agent, runs: list[dict], map_name: str, path: str | Path,
                      samples: int = 3, resolution: int = 40, seed: int = 0,
                      title: str = "", first_agent: int = 0) -> Path:  # fmt: skip
    """Figure 5 / 8: the initiation sets of the options used in ``runs`` (each a density plot)
    with ``samples`` trajectories of each option's policy from stored positive examples;
    agents are labelled ``first_agent + p``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from skillchain_torch.envs.pinball import load_map
    from skillchain_torch.trainers.outputs.option_monitor import plot_initiation_set

    pinball_map = load_map(map_name)
    used = []
    for run in runs:
        for k in dict.fromkeys(int(k) for k in run["options"] if k >= 0):
            if (run["agent"], k) not in used:
                used.append((run["agent"], k))
    if not used:
        raise ValueError("the solutions use no option: nothing to draw")
    cols = min(4, len(used))
    rows = (len(used) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 4 * rows), squeeze=False)
    rng = np.random.default_rng(seed)
    clf = agent.bank.classifier
    for ax, (p, k) in zip(axes.ravel(), used):
        plot_initiation_set(agent.bank, p, k, pinball_map, ax=ax, resolution=resolution,
                            title=f"agent {first_agent + p}, option {k}")  # fmt: skip
        n = int(clf.count[p, k])
        positives = clf.examples[p, k, :n][clf.labels[p, k, :n]]
        inside = positives[clf.contains_points(p, k, positives)] if len(positives) else positives
        pick = rng.choice(len(inside), size=min(samples, len(inside)), replace=False) \
            if len(inside) else []
        color = OPTION_COLORS[k % len(OPTION_COLORS)]
        for i in pick:
            states = option_rollout(agent, p, k, inside[int(i)], map_name)
            ax.plot(states[:, 0], states[:, 1], color=color, lw=1.2)
            ax.plot(states[0, 0], states[0, 1], "o", color=color, ms=4)
    for ax in axes.ravel()[len(used):]:
        ax.axis("off")
    return _save(fig, path, title, dpi=110)
