"""An agent of the user's own composition handed to a trainer (``PopulationTrainer(agent=...)``).

Two things the trainer cannot take from the config when the agent was built outside it:

* :func:`check_agent`: the agent fits the run (its population, observation size and action
  count against the env's), in one line, before the first step fails with a shape error;
* :func:`recorded_config`: what ``config.json`` says about the run. The config's agent fields
  (order, gestation, presets, ...) build an agent *by name*; a user's agent was built by the
  user, so they say nothing about it. They are written as ``null`` and ``agent`` names the
  class, so that the file never describes an agent other than the one that ran.

Example:
    >>> from skillchain_torch.agents import SkillChainingAgent
    >>> from skillchain_torch.options import OptionBank
    >>> from skillchain_torch.trainers import TrainConfig
    >>> agent = SkillChainingAgent(OptionBank.build(population=2, slots=2, order=1), order=1)
    >>> check_agent(agent, TrainConfig(runs=2))
    >>> check_agent(agent, TrainConfig(runs=3))
    Traceback (most recent call last):
    ...
    ValueError: the agent holds 2 agents but the config asks for runs=3
    >>> saved = recorded_config(TrainConfig(runs=2, episodes=5), agent)
    >>> saved["agent"], saved["gestation"], saved["episodes"]
    ('user:SkillChainingAgent', None, 5)
"""

from __future__ import annotations

from typing import Any

__all__ = ["TRAINER_FIELDS", "agent_label", "check_agent", "recorded_config", "run_record"]

# The fields the trainer itself reads (the env, the run's length and seeds, where it computes,
# and the exploration schedule it imposes on any agent); every other field builds the agent.
TRAINER_FIELDS = ("map", "env", "obs_bounds", "obs_dim", "num_actions", "runs", "episodes",
                  "seed", "max_episode_steps", "checkpoint_every", "checkpoint_minutes",
                  "keep_checkpoints", "device",
                  "epsilon_init",
                  "annealing_steps")  # fmt: skip
PINBALL_SIZES = (4, 5)  # observation dims and actions of every Pinball map


def _sizes(agent) -> tuple[int | None, int | None]:
    """The agent's observation size and primitive action count, where it declares them
    (``obs_dim``; ``num_actions``, or ``num_primitives`` for a hierarchical agent)."""
    obs_dim = getattr(agent, "obs_dim", None)
    actions = getattr(agent, "num_actions", getattr(agent, "num_primitives", None))
    return (None if obs_dim is None else int(obs_dim),
            None if actions is None else int(actions))  # fmt: skip


def check_agent(agent, config) -> None:
    """``ValueError`` (one line) unless ``agent`` fits ``config``'s run: ``config.runs``
    agents, and the env's observation size and action count (``config.obs_dim`` /
    ``num_actions``, read from the env's specs; Pinball's 4 and 5 for a map)."""
    if int(agent.population) != config.runs:
        raise ValueError(f"the agent holds {agent.population} agents but the config asks "
                         f"for runs={config.runs}")  # fmt: skip
    want = (config.obs_dim or PINBALL_SIZES[0], config.num_actions or PINBALL_SIZES[1])
    have = _sizes(agent)
    if any(h is not None and h != w for h, w in zip(have, want)):
        raise ValueError(
            f"the agent is built for {have[0]} observation dims and {have[1]} actions but "
            f"{config.env_name} has {want[0]} and {want[1]}: build its pieces for the env "
            f"(e.g. OptionBank.build(..., obs_dim={want[0]}, num_actions={want[1]}))")


def recorded_config(config, agent=None) -> dict[str, Any]:
    """``config`` as ``config.json`` records it: as it is for an agent the trainer built by
    name (``agent`` ``None``); for the user's own agent, the agent fields ``None`` (the
    exploration ``epsilon`` kept only where the trainer anneals it) and ``agent`` set to
    ``"user:<class>"``."""
    data = config.to_dict()
    if agent is None:
        return data
    for name in data:
        if name not in TRAINER_FIELDS:
            data[name] = None
    if config.epsilon_init is not None:  # the trainer sets the agent's epsilon from its schedule
        data["epsilon"] = config.epsilon
    data["agent"] = f"user:{type(agent).__name__}"
    return data


def agent_label(trainer) -> str:
    """The agent's name in titles, progress bars and TensorBoard: the config's kind, or the
    class of the user's own agent."""
    return (type(trainer.agent).__name__ if getattr(trainer, "user_agent", False)
            else trainer.config.agent)  # fmt: skip


def run_record(trainer) -> dict[str, Any]:
    """What ``config.json``, ``diverged.json`` and TensorBoard's hparams record for
    ``trainer``'s run: :func:`recorded_config` of its config and, if the user built it, its
    agent."""
    user = getattr(trainer, "user_agent", False)
    return recorded_config(trainer.config, trainer.agent if user else None)
