"""A greedy solution coloured by the option in control (the paper's Figure 4b).

:func:`greedy_trajectory` replays one agent of a trained population greedily (epsilon 0 at both
levels, learning frozen) on a fresh environment and records the ball's states and the option in
control at each step; :func:`plot_option_trajectory` draws it with each option in its own colour
and primitive actions in black. :func:`best_greedy_trajectory` tries several agents and keeps
the highest return ("a good example solution").

Example:
    >>> import matplotlib; matplotlib.use("Agg")
    >>> from skillchain_torch.trainers import PopulationTrainer, TrainConfig
    >>> trainer = PopulationTrainer(TrainConfig(agent="skill-chaining", map="pinball_box",
    ...                                         runs=2, episodes=1, max_episode_steps=50))
    >>> run = greedy_trajectory(trainer.agent, 0, "pinball_box", max_steps=30)
    >>> run["states"].shape[1], len(run["options"]) == len(run["states"]) - 1
    (4, True)
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from skillchain_torch.agents import HierarchicalAgent
from skillchain_torch.envs.pinball import PinballEnv, load_map

__all__ = ["greedy_trajectory", "best_greedy_trajectory", "solution_rank", "plot_option_trajectory",
           "save_option_trajectory", "OPTION_COLORS"]  # fmt: skip

# Distinct colours for option slots; primitives are black.
OPTION_COLORS = ("tab:red", "tab:blue", "tab:green", "tab:orange", "tab:purple", "tab:cyan",
                 "tab:pink", "tab:olive", "tab:brown", "gold", "lime", "navy")  # fmt: skip


def _single_agent(agent, p: int, epsilon: float = 0.0, seed: int = 0) -> HierarchicalAgent:
    """A frozen copy of agent ``p`` of a population (P = 1), greedy unless ``epsilon > 0``
    (then both levels explore with it, drawing from stream ``seed``)."""
    if not isinstance(agent, HierarchicalAgent):
        raise TypeError("greedy_trajectory needs an agent with options (HierarchicalAgent)")
    # A plain HierarchicalAgent: the options as they are (no discovery, no refits), with the
    # no-overlap rule they were learned under.
    single = HierarchicalAgent(agent.bank.select_agents([p]), order=agent.order, alpha=0.0,
                               gamma=agent.gamma, epsilon=epsilon, option_epsilon=epsilon,
                               seed=seed,
                               events=agent.events, max_option_steps=agent.max_option_steps,
                               overlap=True)
    with torch.no_grad():
        single.q_head.weight.copy_(agent.q_head.weight[p : p + 1])  # (the built-in head)
    for name in ("alpha", "lr"):  # frozen: no intra-option learning on the way
        if hasattr(single.bank.q_head, name):
            setattr(single.bank.q_head, name, 0.0)
    return single


@torch.no_grad()
def greedy_trajectory(agent, p: int, map_name: str, max_steps: int = 2000,
                      seed: int = 0, epsilon: float = 0.0) -> dict:  # fmt: skip
    """Run agent ``p`` greedily (or ``epsilon``-greedily, as it behaved while training) for one
    episode; states ``[T + 1, 4]`` (raw), the option in control at each step ``[T]`` (-1: a
    primitive decision), the return and whether it reached the goal."""
    single = _single_agent(agent, p, epsilon, seed)
    env = PinballEnv(map_name, batch_size=[1], max_episode_steps=max_steps, seed=seed)
    td = env.reset()
    states, options, total = [td["state"][0].clone()], [], 0.0
    action = single.begin(td["observation"].to(torch.float64))
    terminated = False
    for _ in range(max_steps):
        options.append(int(single.options[0]))
        td = env.step(td.set("action", action))
        nxt = td["next"]
        reward = nxt["reward"].reshape(1).to(torch.float64)
        total += float(reward)
        states.append(nxt["state"][0].clone())
        terminated = bool(nxt["terminated"].any())
        if terminated or bool(nxt["truncated"].any()):
            break
        action = single.observe(nxt["observation"].to(torch.float64), reward)
        td = env.step_mdp(td)
    return {"states": torch.stack(states).numpy(), "options": np.array(options),
            "return": total, "terminated": terminated, "agent": p, "epsilon": epsilon}


def best_greedy_trajectory(agent, map_name: str, agents=None, max_steps: int = 2000,
                           tries: int = 4) -> dict:  # fmt: skip
    """The best episode among ``agents`` (default: all) for a Figure 4b ("a good example
    solution"): one that reaches the goal, preferably through options, with the highest
    return. Each agent runs greedily once, then ``tries - 1`` times with the training
    epsilon (0.01, seeds 1, 2, ...): a greedy policy after few episodes often circles where
    one exploratory step would free it."""
    agents = range(agent.population) if agents is None else agents
    runs = [greedy_trajectory(agent, int(p), map_name, max_steps, seed=t,
                              epsilon=0.0 if t == 0 else agent.epsilon)
            for p in agents for t in range(tries)]
    return max(runs, key=solution_rank)


def solution_rank(run: dict) -> tuple:
    """How :func:`best_greedy_trajectory` ranks episodes: reaching the goal, then using an
    option, then the return (``max`` keeps the first of equals)."""
    return run["terminated"], bool((run["options"] >= 0).any()), run["return"]


def plot_option_trajectory(run: dict, map_name: str, ax=None, title: str | None = None):
    """Draw ``run`` (from :func:`greedy_trajectory`): one colour per option slot, black for
    primitive actions, with a legend of the options used."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from skillchain_torch.envs.pinball import plot_trajectories

    if ax is None:
        _, ax = plt.subplots(figsize=(5, 5))
    options = run["options"]
    colors = ["black" if k < 0 else OPTION_COLORS[k % len(OPTION_COLORS)] for k in options]
    plot_trajectories(load_map(map_name), [run["states"]], colors=[colors], ax=ax,
                      linewidth=2.0)  # fmt: skip
    used = sorted(set(int(k) for k in options))
    handles = [Line2D([], [], color="black" if k < 0 else OPTION_COLORS[k % len(OPTION_COLORS)],
                      label="primitive actions" if k < 0 else f"option {k}") for k in used]
    ax.legend(handles=handles, loc="lower left", fontsize=7, framealpha=0.8)
    steps = len(options)
    kind = "greedy" if not run.get("epsilon") else f"epsilon {run['epsilon']:g}"
    ax.set_title(title or f"agent {run['agent']}: {kind} solution, {steps} steps, "
                 f"return {run['return']:,.0f}", fontsize=9)  # fmt: skip
    return ax


def save_option_trajectory(run: dict, map_name: str, path: str | Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ax = plot_option_trajectory(run, map_name)
    ax.figure.tight_layout()
    ax.figure.savefig(path, dpi=130)
    plt.close(ax.figure)
    return Path(path)
