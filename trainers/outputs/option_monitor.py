"""Option monitoring: how much the agents use their options, how the options end, and what
their initiation sets look like, written to TensorBoard.

:class:`OptionMonitor` counts, per agent and option slot, from the read-outs of
:meth:`HierarchicalAgent.transition` (a few additions per step):

* steps under each option slot (and under primitive decisions),
* executions that ended, their summed durations (steps), and how they ended: by the option's
  target event (*success*), by the ``max_option_steps`` limit (*timeout*) or by the end of the
  episode without the target (*episode end*).

When an agent finishes an episode its counters are folded into that episode's totals; when the
slowest agent completes population episode ``e`` (every agent has then done it) these are
written at step ``e``, for every slot that is live in some agent:

* ``options/slot_{k}/step_share``: steps under option k / all steps of episode e (all agents);
  ``options/primitive_step_share``: the rest;
* ``options/slot_{k}/executions``: executions per agent-episode;
* ``options/slot_{k}/mean_duration``: mean steps per execution (when there were executions);
* ``options/slot_{k}/success_rate``, ``timeout_rate``: fractions of the executions;
* ``options/slot_{k}/initiation_size`` (every ``size_every`` population episodes, at the
  first and at the end): the fraction of a fixed probe grid of observations
  (``probe_resolution ** 2`` positions times the 25 velocities of Figure 5) inside the slot's
  initiation set, averaged over the agents where the slot is live;
* ``options/live_slots``: live slots per agent;
* images ``options/initiation/agent_{p}/slot_{k}`` (every ``image_every`` population episodes,
  at the first and at the end): the paper's Figure 5 density of the initiation set (see
  :func:`initiation_density`), obstacles tinted blue and the target red.

With ``per_agent=True`` each agent's share, duration and success rate are also written per
agent-episode (``agent_{p}/option_{k}/...``, step = episode). Counters of an episode in progress
are not saved in checkpoints: after a resume the first episode's counts are partial.

:func:`initiation_density` and :func:`plot_initiation_set` (plain functions for notebooks) live
in :mod:`.initiation_images` and are re-exported here. Example:
``OptionMonitor(logger, size_every=1)`` probes the sets at every episode, as before issue 29.
"""

from __future__ import annotations

import time

import numpy as np
import torch
from torch import Tensor

from skillchain_torch.options import OptionBank

# The plain functions lived here first; re-exported so that existing imports keep working.
from skillchain_torch.trainers.outputs.initiation_images import (
    VELOCITIES,
    SlotMemo,
    board_masks,
    contains_many,
    initiation_density,
    initiation_image,
    plot_initiation_set,
    probe_observations,
)

__all__ = [
    "VELOCITIES",
    "OptionMonitor",
    "probe_observations",
    "contains_many",
    "initiation_density",
    "initiation_image",
    "plot_initiation_set",
]

class OptionMonitor:
    """Count option use from a :class:`HierarchicalAgent`'s transitions; log per episode.

    Args:
        logger: a TorchRL logger with ``log_scalar`` and ``experiment`` (a ``SummaryWriter``),
            e.g. :class:`TensorBoardHook`'s; ``None``: count only (read :meth:`end_episodes`).
        probe_resolution: positions per side of the probe grid for ``initiation_size``.
        size_every: as ``image_every``, for ``initiation_size`` (probing every episode cost
            a quarter of a 10 x 100 run).
        image_every: write initiation-set images every this many population episodes (also at
            the first and at the end); 0: never.
        image_agents: agents whose options are drawn.
        image_resolution: cells per side of the images.
        per_agent: also write per-agent-episode scalars.
        pinball_map: drawn under the images (default: the trainer's env map).
        counting: ``"agent"`` reads the counts a skill-chaining agent's discovery keeps
            anyway (:class:`~skillchain_torch.discovery.skill_chaining.ExecutionCounts`: no
            per-step work; an execution cut by a truncated episode is not counted among the
            executions, though its steps are); ``"step"`` counts every transition; ``None``:
            ``"agent"`` where the agent keeps counts.

    Use :meth:`register` with a :class:`PopulationTrainer` (it attaches to ``trainer.agent``),
    or :meth:`attach` an agent yourself and call :meth:`end_episodes` when episodes end.
    Counting by step registers a hook on the agent
    (:meth:`~skillchain_torch.agents.HierarchicalAgent.register_transition_hook`; :meth:`detach`
    removes it).
    """

    def __init__(self, logger=None, probe_resolution: int = 12, image_every: int = 10,
                 image_agents=(0,), image_resolution: int = 50, per_agent: bool = False,
                 pinball_map=None, size_every: int = 10, counting: str | None = None):
        if counting not in (None, "agent", "step"):
            raise ValueError(f"counting must be 'agent', 'step' or None, got {counting!r}")
        self.counting = counting
        self.logger = logger
        self.probe_resolution = int(probe_resolution)
        self.size_every = int(size_every)
        self._last_size = 0
        self.image_every = int(image_every)
        self.image_agents = tuple(int(p) for p in image_agents)
        self.image_resolution = int(image_resolution)
        self.per_agent = per_agent
        self.pinball_map = pinball_map
        self.agent = None
        self._kept = None  # the agent's own counts (counting="agent"), once attached
        self._sizes: SlotMemo | None = None  # the initiation_size probe grid's memberships
        self._images: SlotMemo | None = None  # the images' grid
        self._masks = None  # (pinball_map, resolution, obstacle and target masks) of the images
        self.seconds = 0.0  # wall time spent monitoring (counting, probing, drawing, writing)
        self._totals: dict[int, dict[str, np.ndarray]] = {}
        self._last_image = 0

    def episode_stats(self, episode: int, pop: bool = False) -> dict[str, np.ndarray]:
        """Statistics of episode ``episode`` (0-based) over the agents that completed it:
        ``step_share [K]``, ``primitive_step_share``, ``executions [K]`` (per agent),
        ``mean_duration``, ``success_rate``, ``timeout_rate`` ``[K]`` (NaN: no execution)."""
        t = self._totals.pop(episode) if pop else self._totals[episode]
        return _stats(t, t["agents"][0])

    # ------------------------------------------------------------------ probing
    @torch.no_grad()
    def initiation_sizes(self) -> np.ndarray:
        """``[P, K]``: fraction of the probe grid inside each live slot's initiation set
        (NaN for empty slots). Slots unchanged since the last call are not probed again."""
        bank = self.agent.bank
        clf = bank.classifier
        if self._sizes is None:
            self._sizes = SlotMemo(probe_observations(self.probe_resolution,
                                                      dtype=clf.weight.dtype,
                                                      device=clf.weight.device,
                                                      dim=clf.obs_dim))
        live = bank.live().cpu().numpy()
        out = np.full(live.shape, np.nan)
        for p, k in zip(*np.nonzero(live)):
            out[p, k] = float(self._sizes.contains(clf, p, k).to(torch.float64).mean())
        return out

    # ------------------------------------------------------------------ trainer hooks
    def register(self, trainer, name: str = "options") -> None:
        """Attach to ``trainer.agent`` and log at the trainer's episode ends."""
        self.attach(trainer.agent)
        if self.pinball_map is None:
            self.pinball_map = getattr(trainer.env, "pinball_map", None)
        trainer.register_op("post_episodes", self.post_episodes, name=name)
        trainer.register_op("post_train", self.post_train, name=name)

    def post_episodes(self, trainer, batch) -> None:
        start = time.perf_counter()
        try:
            self._post_episodes(batch)
        finally:
            self.seconds += time.perf_counter() - start

    def _post_episodes(self, batch) -> None:
        counts = self.end_episodes(batch.agents, batch.episodes, batch.lengths)
        if self.logger is None:
            return
        log = self.logger.log_scalar
        if self.per_agent:
            for row, (p, e) in enumerate(zip(batch.agents, batch.episodes)):
                one = {name: value[row] for name, value in counts.items()}
                one["agents"] = np.ones(1, dtype=np.int64)
                stats = _stats(one, 1)
                for k in np.nonzero(self.agent.bank.live()[p].cpu().numpy())[0]:
                    for key in ("step_share", "mean_duration", "success_rate"):
                        if np.isfinite(stats[key][k]):
                            log(f"agent_{p}/option_{k}/{key}", float(stats[key][k]), step=e + 1)
        episode = batch.population_episode
        if episode is None:
            return
        self.log_episode(episode)
        if self.image_every > 0 and (episode == 1 or episode - self._last_image
                                     >= self.image_every):
            self.log_images(episode)

    def log_episode(self, episode: int) -> None:
        """Write the scalars of population episode ``episode`` (1-based)."""
        log = self.logger.log_scalar
        stats = self.episode_stats(episode - 1, pop=True)
        live = self.agent.bank.live().cpu().numpy()
        log("options/primitive_step_share", float(stats["primitive_step_share"]), step=episode)
        log("options/live_slots", float(live.sum(-1).mean()), step=episode)
        for k in np.nonzero(live.any(0))[0]:
            prefix = f"options/slot_{k}"
            log(f"{prefix}/step_share", float(stats["step_share"][k]), step=episode)
            log(f"{prefix}/executions", float(stats["executions"][k]), step=episode)
            for key in ("mean_duration", "success_rate", "timeout_rate"):
                if np.isfinite(stats[key][k]):
                    log(f"{prefix}/{key}", float(stats[key][k]), step=episode)
        if self.size_every > 0 and (episode == 1 or episode - self._last_size
                                    >= self.size_every):  # fmt: skip
            self.log_sizes(episode)

    def log_sizes(self, episode: int) -> None:
        """Write ``options/slot_{k}/initiation_size`` of the slots live in some agent."""
        self._last_size = episode
        live = self.agent.bank.live().cpu().numpy()
        sizes = self.initiation_sizes()
        for k in np.nonzero(live.any(0))[0]:
            self.logger.log_scalar(f"options/slot_{k}/initiation_size",
                                   float(np.nanmean(sizes[:, k])), step=episode)

    def log_images(self, episode: int) -> None:
        """Write the Figure-5 initiation-set images of ``image_agents``' live slots (a slot
        unchanged since its last image is not probed again, but written again)."""
        self._last_image = episode
        bank = self.agent.bank
        clf = bank.classifier
        R = self.image_resolution
        if self._images is None:
            self._images = SlotMemo(probe_observations(R, dtype=clf.weight.dtype,
                                                       device=clf.weight.device,
                                                       dim=clf.obs_dim))
        live = bank.live().cpu().numpy()
        for p in self.image_agents:
            if p >= live.shape[0]:
                continue
            for k in np.nonzero(live[p])[0]:
                member = self._images.contains(clf, p, int(k)).reshape(R, R, -1)
                density = member.to(torch.float64).mean(-1).cpu().numpy()
                image = initiation_image(density, self.pinball_map, masks=self._board(R))
                self.logger.experiment.add_image(f"options/initiation/agent_{p}/slot_{k}", image,
                                                 episode, dataformats="HWC")

    def _board(self, resolution: int):
        """The images' obstacle and target masks, computed once per map and resolution."""
        if self.pinball_map is None:
            return None
        if (self._masks is None or self._masks[0] is not self.pinball_map
                or self._masks[1] != resolution):  # fmt: skip
            self._masks = (self.pinball_map, resolution,
                           board_masks(self.pinball_map, resolution))
        return self._masks[2]

    def post_train(self, trainer) -> None:
        if self.logger is None:
            return
        start, threads = time.perf_counter(), torch.get_num_threads()
        # After train() torch is back at its default threads; these small ops took 10x
        # longer there on a busy 2-core machine than at the trainer's one thread.
        torch.set_num_threads(getattr(trainer, "num_threads", None) or threads)
        try:
            episode = int(trainer.episodes_done.min())
            if self.size_every > 0 and episode > self._last_size:
                self.log_sizes(episode)
            if self.image_every > 0 and episode > self._last_image:
                self.log_images(episode)
            self.logger.experiment.flush()
        finally:
            torch.set_num_threads(threads)
            self.seconds += time.perf_counter() - start

    # ------------------------------------------------------------------ counting
    def attach(self, agent) -> OptionMonitor:
        """Start counting ``agent``'s transitions (it needs ``bank``, ``events``, ``contains``,
        ``max_option_steps`` and ``register_transition_hook``, as :class:`HierarchicalAgent`)."""
        if self.agent is not None:
            raise RuntimeError("this monitor is already attached to an agent")
        if not isinstance(getattr(agent, "bank", None), OptionBank):
            raise TypeError("the agent has no option bank to monitor")
        counts = getattr(getattr(agent, "discovery", None), "counts", None)
        if self.counting == "agent" and counts is None:
            raise ValueError("counting='agent' needs an agent whose discovery keeps counts "
                             "(SkillChainingAgent)")  # fmt: skip
        if (self.counting == "step" or counts is None) and not callable(
                getattr(agent, "register_transition_hook", None)):  # fmt: skip
            raise TypeError(f"counting by step needs an agent with register_transition_hook "
                            f"(HierarchicalAgent); {type(agent).__name__} has none")
        self.agent = agent
        P, K = agent.bank.population, agent.bank.slots
        device = agent.bank.status.device
        zeros = dict(dtype=torch.int64, device=device)
        # Steps of the current episode under primitive decisions (column 0) and option k
        # (k + 1): one indexed add a step, the per-step cost being most of the monitor's.
        self._tally = torch.zeros(P, K + 1, **zeros)
        self._column = torch.arange(P, device=device) * (K + 1) + 1  # + option = flat index
        # On the CPU through NumPy views: an operation on ten numbers costs far less there.
        self._numpy = device.type == "cpu"
        if self._numpy:
            self._tally_np = self._tally.view(-1).numpy()
            self._column_np = self._column.numpy()
        self.executions = torch.zeros(P, K, **zeros)  # ended executions
        self.execution_steps = torch.zeros(P, K, **zeros)
        self.successes = torch.zeros(P, K, **zeros)
        self.timeouts = torch.zeros(P, K, **zeros)
        self._slots = torch.arange(K, device=device)
        self._kept = counts if self.counting != "step" else None
        if self._kept is not None:  # the agent counts: nothing to do per step
            return self

        def count(info, next_obs, terminated, stepped):
            start = time.perf_counter()
            self._count(info, next_obs, terminated, stepped)
            self.seconds += time.perf_counter() - start

        self._hook = agent.register_transition_hook(count)
        return self

    def detach(self) -> None:
        """Stop counting (the agent's transition hook is removed)."""
        if self.agent is not None:
            if self._kept is None:
                self._hook.remove()
            self.agent = None

    @property
    def steps(self) -> Tensor:
        """``[P]`` steps of the current episode."""
        return self._tally.sum(-1)

    @property
    def option_steps(self) -> Tensor:
        """``[P, K]`` steps of the current episode under each option."""
        return self._tally[:, 1:]

    def _count(self, info: dict, next_obs: Tensor, terminated: Tensor, stepped: Tensor) -> None:
        if self._numpy:  # (no torch.no_grad() there: entering it cost more than the count)
            return self._count_numpy(info, next_obs, terminated, stepped)
        with torch.no_grad():
            self._count_torch(info, next_obs, terminated, stepped.to(torch.bool))

    def _count_torch(self, info, next_obs, terminated, stepped) -> None:
        option = info["option"]
        self._tally.view(-1).index_add_(0, self._column + option, stepped.to(torch.int64))
        executed = info["decision_ended"] & (option >= 0) & stepped  # an execution ended
        if not bool(executed.any()):
            return
        ended = (option[:, None] == self._slots) & executed[:, None]  # [P, K]
        duration = info["duration"][:, None]
        self.executions += ended
        self.execution_steps += ended * duration
        reached = self._reached(info, next_obs, terminated, stepped)
        self.successes += ended & reached
        self.timeouts += ended & ~reached & (duration >= self.agent.max_option_steps)

    def _count_numpy(self, info, next_obs, terminated, stepped) -> None:
        """The same counts on NumPy views (a (row, slot) index is distinct: ``+=`` adds once)."""
        if stepped.dtype != torch.bool:
            stepped = stepped.to(torch.bool)
        option_np, stepped_np = info["option"].numpy(), stepped.numpy()
        self._tally_np[self._column_np + option_np] += stepped_np
        executed = info["decision_ended"].numpy() & (option_np >= 0) & stepped_np
        if not executed.any():
            return
        rows = np.flatnonzero(executed)
        slots = option_np[rows]
        duration = info["duration"].numpy()[rows]
        reached = self._reached(info, next_obs, terminated, stepped).numpy()[rows, slots]
        self.executions.numpy()[rows, slots] += 1
        self.execution_steps.numpy()[rows, slots] += duration
        self.successes.numpy()[rows, slots] += reached
        self.timeouts.numpy()[rows, slots] += ~reached & (duration >= self.agent.max_option_steps)

    def _reached(self, info, next_obs, terminated, stepped) -> Tensor:
        """``[P, K]``: each option's target event at ``s'``."""
        reached = info.get("reached")
        if reached is None:  # an agent that does not report its options' targets
            agent = self.agent
            terminated = terminated.to(torch.bool) & stepped
            with torch.no_grad():
                reached = agent.bank.target_reached(next_obs, terminated, agent.events,
                                                    contains=agent.contains)
        return reached

    _COUNTERS = ("steps", "option_steps", "executions", "execution_steps", "successes",
                 "timeouts")

    def counts(self, agents=None) -> dict[str, np.ndarray]:
        """The current (unfinished episode) counters of ``agents`` (default all) as numpy."""
        index = slice(None) if agents is None else torch.as_tensor(agents, dtype=torch.int64)
        return {name: getattr(self, name)[index].cpu().numpy() for name in self._COUNTERS}

    def end_episodes(self, agents, episodes, lengths=None) -> dict[str, np.ndarray]:
        """Fold the counters of ``agents`` (their episodes ``episodes``, 0-based; ``lengths``:
        their steps, needed when the agent keeps the counts) into the episode totals, reset
        them, and return their per-agent counts."""
        index = torch.as_tensor(list(agents), dtype=torch.int64,
                                device=self.steps.device)
        counts = self.counts(index) if self._kept is None else self._agent_counts(index, lengths)
        self._tally[index] = 0
        for name in self._COUNTERS[2:]:
            getattr(self, name)[index] = 0
        K = self.option_steps.shape[1]
        for row, episode in enumerate(episodes):
            total = self._totals.setdefault(int(episode), {
                "agents": np.zeros(1, dtype=np.int64), "steps": np.zeros(1, dtype=np.int64),
                **{name: np.zeros(K, dtype=np.int64) for name in self._COUNTERS[1:]}})
            total["agents"] += 1
            for name in self._COUNTERS:
                total[name] += counts[name][row]
        return counts

    def _agent_counts(self, index: Tensor, lengths) -> dict[str, np.ndarray]:
        """The counters of the agents ``index`` from their last episode's kept counts."""
        if lengths is None:
            raise ValueError("end_episodes needs the episodes' lengths when the agent keeps "
                             "the counts (counting='agent')")  # fmt: skip
        kept = self._kept
        outcomes = kept.last_outcomes[index].cpu().numpy()  # [n, K, 3]
        steps = kept.last_steps[index].cpu().numpy()
        return {"steps": np.asarray(lengths, dtype=np.int64), "option_steps": steps,
                "executions": outcomes.sum(-1), "execution_steps": steps,
                "successes": outcomes[..., 0], "timeouts": outcomes[..., 1]}


def _stats(total: dict, agents: int) -> dict[str, np.ndarray]:
    steps = max(int(np.asarray(total["steps"]).sum()), 1)
    option_steps = total["option_steps"].astype(np.float64)
    executions = total["executions"].astype(np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_duration = np.where(executions > 0, total["execution_steps"] / executions, np.nan)
        success = np.where(executions > 0, total["successes"] / executions, np.nan)
        timeout = np.where(executions > 0, total["timeouts"] / executions, np.nan)
    return {
        "step_share": option_steps / steps,
        "primitive_step_share": 1.0 - option_steps.sum() / steps,
        "executions": executions / max(int(agents), 1),
        "mean_duration": mean_duration,
        "success_rate": success,
        "timeout_rate": timeout,
    }
