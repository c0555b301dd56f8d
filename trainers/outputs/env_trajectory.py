"""Figure 4b off Pinball: one episode of a trained agent in a Gymnasium/TorchRL env, coloured by
the option in control.

:func:`env_trajectory` replays agent ``p`` of a trained population (a frozen single-agent copy,
as :func:`~.option_trajectory.greedy_trajectory` does on Pinball) for one episode of a fresh env
and records the observation (in the unit box the agent sees) and the option in control at each
step; :func:`plot_env_trajectory` draws observation dims 0 and 1 (MountainCar: position and
velocity; Acrobot: cos and sin of the first joint), each option in its own colour, primitive
actions in black.

Example:
    >>> import matplotlib; matplotlib.use("Agg")
    >>> from skillchain_torch.trainers import PopulationTrainer, TrainConfig
    >>> trainer = PopulationTrainer(TrainConfig(agent="skill-chaining", runs=2, episodes=1,
    ...     env="gymnasium:MountainCar-v0", max_episode_steps=30)).train()
    >>> run = env_trajectory(trainer.agent, 0, "gymnasium:MountainCar-v0", max_steps=30)
    >>> run["states"].shape, len(run["options"])
    ((31, 2), 30)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from skillchain_torch.envs.external import make_env, read_specs
from skillchain_torch.trainers.outputs.option_trajectory import (
    OPTION_COLORS,
    _frozen_agents,
    solution_rank,
)

__all__ = ["env_trajectory", "best_env_trajectory", "plot_env_trajectory",
           "save_env_trajectory"]  # fmt: skip


@torch.no_grad()
def env_trajectory(agent, p: int, env_spec: str, max_steps: int = 1000, seed: int = 0,
                   epsilon: float = 0.0, obs_bounds: str | None = None) -> dict:  # fmt: skip
    """Agent ``p`` for one episode of ``env_spec`` (seeded ``seed``), greedy unless
    ``epsilon``: observations ``[T + 1, D]`` (unit box), the option in control at each step
    ``[T]`` (-1: a primitive decision), the return and whether the episode terminated."""
    single = _frozen_agents(agent, [p], epsilon, [seed])
    env = make_env(env_spec, seed=seed)
    sizes = read_specs(env, obs_bounds)
    td = env.reset()
    obs = sizes.scale(td["observation"])[None]
    states, options, total, terminated = [obs[0]], [], 0.0, False
    action = single.begin(obs)
    for _ in range(max_steps):
        options.append(int(single.options[0]))
        nxt = env.step(td.set("action", action[0].clone())).get("next")
        reward = float(nxt["reward"].reshape(-1)[0])
        total += reward
        obs = sizes.scale(nxt["observation"])[None]
        states.append(obs[0])
        terminated = bool(nxt["terminated"].any())
        if terminated or bool(nxt["truncated"].any()):
            break
        action = single.observe(obs, torch.tensor([reward], dtype=torch.float64))
        td = nxt
    return {"states": torch.stack(states).numpy(), "options": np.array(options),
            "return": total, "terminated": terminated, "agent": p, "epsilon": epsilon,
            "env": env_spec}  # fmt: skip


def best_env_trajectory(agent, env_spec: str, agents=None, max_steps: int = 1000,
                        tries: int = 2, obs_bounds: str | None = None) -> dict:  # fmt: skip
    """The best of ``tries`` episodes per agent (the first greedy, the others at the training
    epsilon), ranked as on Pinball: terminated, through an option, the return."""
    agents = range(agent.population) if agents is None else agents
    runs = [env_trajectory(agent, int(p), env_spec, max_steps, seed=t,
                           epsilon=0.0 if t == 0 else agent.epsilon, obs_bounds=obs_bounds)
            for p in agents for t in range(tries)]  # fmt: skip
    return max(runs, key=solution_rank)


def plot_env_trajectory(run: dict, ax=None, dims: tuple[int, int] = (0, 1),
                        title: str | None = None):  # fmt: skip
    """Draw ``run`` in observation dims ``dims``: one colour per option, black for primitives."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    if ax is None:
        _, ax = plt.subplots(figsize=(5, 5))
    states, options = run["states"], run["options"]
    for t, k in enumerate(options):
        color = "black" if k < 0 else OPTION_COLORS[k % len(OPTION_COLORS)]
        ax.plot(states[t:t + 2, dims[0]], states[t:t + 2, dims[1]], color=color, linewidth=1.5)
    ax.plot(*states[0, list(dims)], "o", color="gray", label="start")
    used = sorted(set(int(k) for k in options))
    handles = [Line2D([], [], color="black" if k < 0 else OPTION_COLORS[k % len(OPTION_COLORS)],
                      label="primitive actions" if k < 0 else f"option {k}") for k in used]
    ax.legend(handles=handles, loc="best", fontsize=7, framealpha=0.8)
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.set_xlabel(f"observation dim {dims[0]} (scaled to [0, 1])")
    ax.set_ylabel(f"observation dim {dims[1]} (scaled to [0, 1])")
    kind = "greedy" if not run.get("epsilon") else f"epsilon {run['epsilon']:g}"
    ax.set_title(title or f"{run['env']}, agent {run['agent']}: {kind}, {len(options)} steps, "
                 f"return {run['return']:,.0f}", fontsize=8)  # fmt: skip
    return ax


def save_env_trajectory(run: dict, path: str | Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ax = plot_env_trajectory(run)
    ax.figure.tight_layout()
    ax.figure.savefig(path, dpi=130)
    plt.close(ax.figure)
    return Path(path)
