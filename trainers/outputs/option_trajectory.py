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

import math
from pathlib import Path

import numpy as np
import torch

from skillchain_torch.agents import HierarchicalAgent
from skillchain_torch.envs.pinball import PinballEnv, load_map
from skillchain_torch.envs.pinball.physics import GOAL_REWARD
from skillchain_torch.modules import LinearQHead

__all__ = ["greedy_trajectory", "greedy_trajectories", "best_greedy_trajectory", "solution_rank",
           "figure_candidates",
           "plot_option_trajectory", "save_option_trajectory", "OPTION_COLORS"]  # fmt: skip

# Distinct colours for option slots; primitives are black.
# (No olive beside gold, no grey: each slot's colour stands apart from the others and from black.)
OPTION_COLORS = ("tab:red", "tab:blue", "tab:green", "tab:orange", "tab:purple", "tab:cyan",
                 "tab:pink", "tab:brown", "magenta", "lime", "navy", "teal")  # fmt: skip


def _single_agent(agent, p: int, epsilon: float = 0.0, seed: int = 0) -> HierarchicalAgent:
    """A frozen copy of agent ``p`` of a population (P = 1), greedy unless ``epsilon > 0``
    (then both levels explore with it, drawing from stream ``seed``)."""
    return _frozen_agents(agent, [p], epsilon, [seed])


def _frozen_agents(agent, rows, epsilon: float, seeds) -> HierarchicalAgent:
    """Frozen copies of agents ``rows`` (repeats allowed), row ``i`` drawing from stream
    ``seeds[i]``: row ``i`` behaves as ``_single_agent(agent, rows[i], epsilon, seeds[i])``,
    since every step of the agent is row-independent."""
    if not isinstance(agent, HierarchicalAgent):
        raise TypeError("greedy_trajectory needs an agent with options (HierarchicalAgent)")
    rows = [int(p) for p in rows]
    # A plain HierarchicalAgent: the options as they are (no discovery, no refits), with the
    # no-overlap rule they were learned under.
    head = agent.q_head
    own = {}  # a head of the user's own: its rows, on the agent's features
    if type(head) is not LinearQHead:
        if not hasattr(head, "select_agents"):
            raise TypeError(f"replaying needs the top-level head's rows: {type(head).__name__}"
                            " has no select_agents(rows)")  # fmt: skip
        own = {"q_head": head.select_agents(rows), "features": agent.features}
    frozen = HierarchicalAgent(agent.bank.select_agents(rows), order=agent.order, alpha=0.0,
                               gamma=agent.gamma, epsilon=epsilon, option_epsilon=epsilon,
                               seed=torch.tensor([int(s) for s in seeds], dtype=torch.int64),
                               events=tuple(_event_rows(e, rows) for e in agent.events),
                               max_option_steps=agent.max_option_steps,
                               overlap=True, **own)  # fmt: skip
    if not own:
        with torch.no_grad():
            frozen.q_head.weight.copy_(head.weight[rows])
    for name in ("alpha", "lr"):  # frozen: no intra-option learning on the way
        if hasattr(frozen.bank.q_head, name):
            setattr(frozen.bank.q_head, name, 0.0)
    return frozen


def _event_rows(event, rows):
    """A base event for agents ``rows``: its own rows where it holds a value per agent
    (``select_agents``, as a random subgoal's centre), else the event itself."""
    return event.select_agents(rows) if hasattr(event, "select_agents") else event


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


@torch.no_grad()
def greedy_trajectories(agent, map_name: str, runs, max_steps: int = 2000) -> list[dict]:
    """Many :func:`greedy_trajectory` episodes at once: ``runs`` lists ``(p, seed, epsilon)``,
    and the result ``i`` equals ``greedy_trajectory(agent, p, map_name, max_steps, seed,
    epsilon)`` of ``runs[i]`` bit for bit.

    The episodes of one epsilon step as one population: one agent step and one physics step
    for all of them instead of one each (a replay is a few thousand tiny steps, so per-call
    overhead is most of its cost). Each row's start is the one its own seed draws, and a
    finished row leaves the agent (its ball idles in the env, never read again).

    Example:
        >>> from skillchain_torch.trainers import PopulationTrainer, TrainConfig
        >>> trainer = PopulationTrainer(TrainConfig(agent="skill-chaining", map="pinball_box",
        ...                                         runs=2, episodes=1, max_episode_steps=50))
        >>> a, b = greedy_trajectories(trainer.agent, "pinball_box", [(0, 0, 0.0), (1, 1, 0.01)],
        ...                            max_steps=30)
        >>> len(a["options"]) == len(a["states"]) - 1, b["epsilon"]
        (True, 0.01)
    """
    return _replays(agent, map_name, runs, max_steps)


def _replays(agent, map_name: str, runs, max_steps: int, best: list[float] | None = None):
    runs = [(int(p), int(seed), float(eps)) for p, seed, eps in runs]
    out: list[dict | None] = [None] * len(runs)
    for epsilon in dict.fromkeys(eps for _, _, eps in runs):  # in order of first use
        group = [i for i, run in enumerate(runs) if run[2] == epsilon]
        replays = _replay(agent, map_name, [runs[i][0] for i in group],
                          [runs[i][1] for i in group], epsilon, max_steps, best)
        for i, replay in zip(group, replays):
            out[i] = replay
    return out


def _replay(agent, map_name: str, rows, seeds, epsilon: float, max_steps: int,
            best: list[float] | None = None) -> list[dict | None]:
    """One batched replay (see :func:`greedy_trajectories`). With ``best`` (a one-element
    list: the highest return of a finished episode that reached the goal through options, or
    -inf), episodes that can no longer beat it stop early and read ``None``: the rest of an
    episode adds at most the goal's reward, so one whose return plus that is below ``best``
    ranks strictly lower under :func:`solution_rank` whatever it does next. ``best`` is
    raised as episodes finish."""
    n = len(rows)
    frozen = _frozen_agents(agent, rows, epsilon, seeds)
    starts = [PinballEnv(map_name, batch_size=[1], seed=s) for s in seeds]
    obs = torch.cat([env.reset_raw() for env in starts])  # each row's own start
    env = PinballEnv(map_name, batch_size=[n], max_episode_steps=max_steps, seed=0)
    env.set_state(torch.cat([start.state for start in starts]))
    first = env.state
    states = [[first[r]] for r in range(n)]
    options: list[list[int]] = [[] for _ in range(n)]
    totals, terminated, hopeless = [0.0] * n, [False] * n, [False] * n
    live = list(range(n))  # env rows whose episode runs, in the agent's row order
    action = frozen.begin(obs.to(torch.float64))
    full = torch.full((n,), 4, dtype=torch.int64)  # finished rows idle (action 4: none)
    for _ in range(max_steps):
        index = torch.tensor(live, dtype=torch.int64)
        for r, k in zip(live, frozen.options.tolist()):
            options[r].append(k)
        full[index] = action
        obs, reward, term, trunc = env.step_raw(full)
        state, rewards = env.state, reward.tolist()
        ended = (term | trunc).tolist()
        for r in live:
            totals[r] += rewards[r]
            states[r].append(state[r])
            terminated[r] = bool(term[r])
            if best is not None and terminated[r] and any(k >= 0 for k in options[r]):
                best[0] = max(best[0], totals[r])
        if best is not None:  # a margin of 1 keeps float sums of whole rewards safe
            for r in live:
                if not ended[r] and totals[r] + GOAL_REWARD < best[0] - 1.0:
                    ended[r] = hopeless[r] = True
        if any(ended[r] for r in live):
            frozen.compact(torch.tensor([not ended[r] for r in live]))
            live = [r for r in live if not ended[r]]
            if not live:
                break
            index = torch.tensor(live, dtype=torch.int64)
        action = frozen.observe(obs[index].to(torch.float64), reward[index].to(torch.float64))
    return [None if hopeless[r] else
            {"states": torch.stack(states[r]).numpy(), "options": np.array(options[r]),
             "return": totals[r], "terminated": terminated[r], "agent": rows[r],
             "epsilon": epsilon} for r in range(n)]  # fmt: skip


def best_greedy_trajectory(agent, map_name: str, agents=None, max_steps: int = 2000,
                           tries: int = 4) -> dict:  # fmt: skip
    """The best episode among ``agents`` (default: all) for a Figure 4b ("a good example
    solution"): one that reaches the goal, preferably through options, with the highest
    return. Each agent runs greedily once, then ``tries - 1`` times with the training
    epsilon (0.01, seeds 1, 2, ...): a greedy policy after few episodes often circles where
    one exploratory step would free it. The episodes run batched
    (:func:`greedy_trajectories`), the same bits as one at a time, and an episode stops as
    soon as it can no longer be the best (see ``_replay``): the same choice, sooner."""
    agents = range(agent.population) if agents is None else agents
    runs = [(int(p), t, 0.0 if t == 0 else agent.epsilon) for p in agents for t in range(tries)]
    # The bound is shared by the groups: the greedy episodes, replayed first, usually set it.
    out = _replays(agent, map_name, runs, max_steps, best=[-math.inf])
    # An episode stopped early (None) ranks strictly below a finished one; the order of the
    # rest is kept, so max picks the one the episodes run in full would pick.
    return max((run for run in out if run is not None), key=solution_rank)


def figure_candidates(held, last_returns=None) -> list[int]:
    """The agents whose episodes Figure 4b (``option_trajectory.png``) draws from, in order: on
    Pinball (``last_returns`` given) the eight that hold the most options, ties to the best last
    return; off Pinball (``None``) the two that hold the most (the replay runs the torch path,
    which is slow). ``held [P]``: live options per agent.

    Example:
        >>> figure_candidates([1, 3, 3, 0], last_returns=[5.0, 1.0, 2.0, 9.0])
        [2, 1, 0, 3]
        >>> figure_candidates([1, 3, 3, 0])
        [1, 2]
    """
    agents = range(len(held))
    if last_returns is None:
        return sorted(agents, key=lambda p: -held[p])[:2]
    last = np.nan_to_num(np.asarray(last_returns, dtype=np.float64), nan=-np.inf)
    return sorted(agents, key=lambda p: (-held[p], -last[p]))[:8]


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
    # Below the map, not over it: a legend box over the start once greyed the path under it.
    ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.06), fontsize=7,
              ncol=min(4, len(handles)), frameon=False)  # fmt: skip
    steps = len(options)
    kind = ("a greedy episode" if not run.get("epsilon")
            else f"an episode exploring at epsilon {run['epsilon']:g}, as in training")
    ax.set_title(title or f"agent {run['agent']}: {kind}\n{steps} steps, return "
                 f"{run['return']:,.0f}; colour: the option in control", fontsize=9)  # fmt: skip
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
