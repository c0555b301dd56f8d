"""What skill chaining discovered: option counts per episode, the option trees, TensorBoard.

:class:`DiscoveryLog` is a trainer hook for agents with a ``discovery``
(:class:`~skillchain_torch.discovery.SkillChaining`). At every episode end it records how many
options the agent holds (``n_options [P, E]``, written as ``DIR/n_options.npy``) and how its
option executions ended (``outcomes [P, E, 3]``: successes, timeouts, episode ends; written as
``DIR/option_outcomes.npy``), and drains the discovery events. To TensorBoard (through the
run's TorchRL logger) it writes:

* ``discovery/events`` (text): every creation, end of gestation, learned set and full agent;
* ``agent_{p}/options``, per agent-episode; when the slowest agent completes an episode:
  ``discovery/options_mean`` and ``_max`` (live options per agent), ``discovery/chain_depth_mean``
  and ``_max`` (the deepest option of each agent: 1 targets the goal, 2 targets a depth-1
  option's set, ...), ``discovery/created``, ``discovery/learned`` (totals over agents so far)
  and ``discovery/agents_slots_full``;
* ``discovery/success_rate``, ``discovery/timeout_rate`` (of the executions ended in the
  population episode, all agents and options);
* ``discovery/learned/agent_{p}/slot_{k}`` (image): the Figure-5 density of each option's
  initiation set when it is learned (for the agents in ``image_agents``).

:func:`option_tree` is the per-agent tree that the CLI writes as ``DIR/option_tree.json``.

Example:
    >>> from skillchain_torch.trainers import PopulationTrainer, TrainConfig
    >>> trainer = PopulationTrainer(TrainConfig(agent="skill-chaining", runs=2, episodes=2,
    ...                                         max_episode_steps=20, slots=2))
    >>> log = DiscoveryLog()
    >>> log.register(trainer)
    >>> _ = trainer.train()
    >>> log.n_options.shape, option_tree(trainer.agent)["agents"][0]["options"]
    ((2, 2), [])
"""

from __future__ import annotations

from collections import Counter

import numpy as np
import torch

from skillchain_torch.discovery.skill_chaining import OUTCOMES
from skillchain_torch.options import OptionStatus
from skillchain_torch.trainers.outputs.timed import TimedHook

__all__ = ["DiscoveryLog", "option_tree"]


def option_tree(agent, slot_outcomes: np.ndarray | None = None) -> dict:
    """Every agent's options: slot, parent slot (-1: a base event), target name, creation
    episode (0-based), status name and depth, as a JSON-ready dict; with ``slot_outcomes``
    (``[P, K, 3]``, :attr:`DiscoveryLog.slot_outcomes`) also each option's executions over the
    run: ``successes``, ``timeouts``, ``episode_ends``."""
    bank, discovery = agent.bank, agent.discovery
    status = bank.status.cpu().tolist()
    parent = bank.parent.cpu().tolist()
    created = bank.created_episode.cpu().tolist()
    depth = discovery.depth().cpu().tolist()
    agents = []
    for p in range(bank.population):
        options = [
            {"slot": k, "parent": parent[p][k], "target": discovery.target_name(p, k),
             "created_episode": created[p][k], "status": OptionStatus(status[p][k]).name,
             "depth": depth[p][k],
             **({} if slot_outcomes is None else dict(zip(
                 ("successes", "timeouts", "episode_ends"),
                 (int(n) for n in slot_outcomes[p, k]))))}
            for k in range(bank.slots) if status[p][k] != OptionStatus.EMPTY
        ]  # fmt: skip
        agents.append({"agent": p, "options": options,
                       "slots_full": bool(discovery.slots_full_logged[p])})  # fmt: skip
    return {"slots": bank.slots, "base_events": [e.name for e in discovery.events],
            "agents": agents}  # fmt: skip


class DiscoveryLog(TimedHook):
    """Record options per episode and log discovery events (see the module docstring).

    Args:
        logger: a TorchRL logger (``log_scalar``, ``experiment``); ``None`` records only.
        image_agents: agents whose learned initiation sets are drawn.
        image_resolution: cells per side of those images.
    """

    def __init__(self, logger=None, image_agents=(0,), image_resolution: int = 50):
        self.logger = logger
        self.image_agents = tuple(int(p) for p in image_agents)
        self.image_resolution = int(image_resolution)
        self.n_options: np.ndarray | None = None
        self.outcomes: np.ndarray | None = None
        self.slot_outcomes: np.ndarray | None = None  # [P, K, 3]: each option's, whole run
        self.totals: Counter = Counter()
        self._map = None
        self.seconds = 0.0  # wall time in the hooks (recorded in run_info.json)

    def register(self, trainer, name: str = "discovery") -> None:
        if getattr(trainer.agent, "discovery", None) is None:
            raise TypeError("the trainer's agent does not discover options")
        P, E = trainer.config.runs, trainer.config.episodes
        if self.n_options is None:
            self.n_options = np.full((P, E), -1, dtype=np.int64)
        if self.outcomes is None:
            self.outcomes = np.zeros((P, E, len(OUTCOMES)), dtype=np.int64)
        if self.slot_outcomes is None:
            K = trainer.agent.bank.slots
            self.slot_outcomes = np.zeros((P, K, len(OUTCOMES)), dtype=np.int64)
        self._map = getattr(trainer.env, "pinball_map", None)
        trainer.register_op("post_episodes", self.post_episodes, name=name)
        trainer.register_op("post_train", self.post_train, name=name)
        trainer.register_module(name, self)

    def _post_episodes(self, trainer, batch) -> None:
        agent = trainer.agent
        live = agent.bank.live().sum(-1).cpu().numpy()
        self.n_options[batch.agents, batch.episodes] = live[batch.agents]
        per_slot = agent.discovery.counts.last_outcomes.cpu().numpy()  # [P, K, 3]
        self.outcomes[batch.agents, batch.episodes] = per_slot.sum(1)[batch.agents]
        np.add.at(self.slot_outcomes, batch.agents, per_slot[batch.agents])
        events = agent.discovery.drain()
        self.totals.update(e.kind for e in events)
        if self.logger is None:
            return
        writer = self.logger.experiment
        if events:
            lines = [_describe(e) for e in events]
            step = int(trainer.episodes_done.max())
            writer.add_text("discovery/events", "  \n".join(lines), step)
        for event in events:
            if event.kind == "learned" and event.agent in self.image_agents:
                self._image(agent, event)
        for p, e in zip(batch.agents, batch.episodes):
            self.logger.log_scalar(f"agent_{p}/options", float(live[p]), step=e + 1)
        episode = batch.population_episode
        if episode is None:
            return
        depth = agent.discovery.depth().amax(-1).cpu().numpy()
        log = self.logger.log_scalar
        log("discovery/options_mean", float(live.mean()), step=episode)
        log("discovery/options_max", float(live.max()), step=episode)
        log("discovery/chain_depth_mean", float(depth.mean()), step=episode)
        log("discovery/chain_depth_max", float(depth.max()), step=episode)
        for kind in ("created", "learned"):
            log(f"discovery/{kind}", float(self.totals[kind]), step=episode)
        full = float(agent.discovery.slots_full_logged.sum())
        log("discovery/agents_slots_full", full, step=episode)
        ended = self.outcomes[:, episode - 1].sum(0)
        if ended.sum() > 0:
            log("discovery/success_rate", float(ended[0] / ended.sum()), step=episode)
            log("discovery/timeout_rate", float(ended[1] / ended.sum()), step=episode)

    def _image(self, agent, event) -> None:
        from skillchain_torch.trainers.outputs.initiation_images import (
            initiation_density,
            initiation_image,
        )

        density = initiation_density(agent.bank, event.agent, event.slot, self.image_resolution)
        image = initiation_image(density, self._map)
        self.logger.experiment.add_image(f"discovery/learned/agent_{event.agent}/slot_{event.slot}",
                                         image, event.episode + 1, dataformats="HWC")

    def post_train(self, trainer) -> None:
        if self.logger is not None:
            self.logger.experiment.flush()

    def state_dict(self) -> dict:
        return {"n_options": torch.from_numpy(self.n_options.copy()),
                "outcomes": torch.from_numpy(self.outcomes.copy()),
                "slot_outcomes": torch.from_numpy(self.slot_outcomes.copy()),
                "totals": dict(self.totals)}  # fmt: skip

    def load_state_dict(self, state: dict) -> None:
        from skillchain_torch.trainers.loop.population import _widened

        # A run extended by --resume --episodes keeps the room registered for its new length.
        episodes = max(state["n_options"].shape[1],
                       0 if self.n_options is None else self.n_options.shape[1])
        self.n_options = _widened(state["n_options"].numpy(), episodes, -1)
        if "outcomes" in state:  # (not in checkpoints saved before the counts were kept)
            self.outcomes = _widened(state["outcomes"].numpy(), episodes, 0)
        if "slot_outcomes" in state:  # (nor before each option's were)
            self.slot_outcomes = state["slot_outcomes"].numpy().copy()
        self.totals = Counter(state["totals"])


def _describe(event) -> str:
    where = f"agent {event.agent}, episode {event.episode + 1}"
    if event.kind == "created":
        return f"{where}: created option {event.slot} targeting {event.target}"
    if event.kind == "joined":
        return (f"{where}: option {event.slot} ({event.target}) joined the decisions, "
                f"Q(s, o) = {event.value:.1f}")
    if event.kind == "learned":
        return f"{where}: option {event.slot}'s initiation set learned; now a target event"
    return f"{where}: all option slots used; no more options"
