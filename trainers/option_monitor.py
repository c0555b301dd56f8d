"""Option monitoring: how much the agents use their options, how the options end, and what
their initiation sets look like, written to TensorBoard.

:class:`OptionMonitor` counts, per agent and option slot, from the read-outs of
:meth:`HierarchicalAgent.transition` (a few ``[P]`` / ``[P, K]`` tensor additions per step; the
target predicates are re-evaluated only on steps where some option execution ended):

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
* ``options/slot_{k}/initiation_size``: the fraction of a fixed probe grid of observations
  (``probe_resolution ** 2`` positions times the 25 velocities of Figure 5) inside the slot's
  initiation set, averaged over the agents where the slot is live;
* ``options/live_slots``: live slots per agent;
* images ``options/initiation/agent_{p}/slot_{k}`` (every ``image_every`` population episodes,
  at the first and at the end): the paper's Figure 5 density of the initiation set (see
  :func:`initiation_density`), obstacles tinted blue and the target red.

With ``per_agent=True`` each agent's share, duration and success rate are also written per
agent-episode (``agent_{p}/option_{k}/...``, step = episode). Counters of an episode in progress
are not saved in checkpoints: after a resume the first episode's counts are partial.

:func:`initiation_density` and :func:`plot_initiation_set` are plain functions for notebooks.

Example:
    >>> import torch
    >>> from skillchain_torch.options import InitiationClassifier
    >>> clf = InitiationClassifier(1, 1)
    >>> with torch.no_grad():
    ...     clf.weight[0, 0, 1] = -1.0; clf.bias[0, 0] = 0.5   # x < 0.5
    ...     clf.trained[0, 0] = True
    >>> d = initiation_density(clf, 0, 0, resolution=4)
    >>> d.tolist()[0]                                          # one row: y fixed, x varies
    [1.0, 1.0, 0.0, 0.0]
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from skillchain_torch.options import InitiationClassifier, OptionBank

__all__ = [
    "VELOCITIES",
    "OptionMonitor",
    "probe_observations",
    "contains_many",
    "initiation_density",
    "initiation_image",
    "plot_initiation_set",
]

# Figure 5: xdot and ydot sampled over {-1, -1/2, 0, 1/2, 1} (raw velocities).
VELOCITIES = (-1.0, -0.5, 0.0, 0.5, 1.0)


def probe_observations(resolution: int = 50, velocities=VELOCITIES,
                       dtype: torch.dtype = torch.float64, device=None, dim: int = 4) -> Tensor:
    """Observations ``[R * R * V * V, 4]`` of a Figure-5 probe grid.

    Positions are the centres of an ``R x R`` grid on the unit board, velocities every pair of
    ``velocities`` (raw, mapped to the descriptor ``(v + 1) / 2``). The order is
    ``(y, x, xdot, ydot)`` from slowest to fastest, so a result reshaped to
    ``[R, R, V * V]`` is indexed ``[row = y, column = x, velocity pair]``.

    Off Pinball (``dim != 4``) the grid spans observation dims 0 and 1 of the unit box and the
    other dims sit at the centre, 0.5: ``[R * R, dim]``, a slice of the set.
    """
    if resolution < 1:
        raise ValueError(f"resolution must be >= 1, got {resolution}")
    centres = (torch.arange(resolution, dtype=dtype, device=device) + 0.5) / resolution
    if dim != 4:
        y, x = torch.meshgrid(centres, centres, indexing="ij")
        rest = torch.full((resolution * resolution, max(dim - 2, 0)), 0.5, dtype=dtype,
                          device=device)  # fmt: skip
        return torch.cat([x.reshape(-1, 1), y.reshape(-1, 1), rest], dim=1)[:, :dim]
    vel = (torch.as_tensor(velocities, dtype=dtype, device=device) + 1.0) / 2.0
    y, x, vx, vy = torch.meshgrid(centres, centres, vel, vel, indexing="ij")
    return torch.stack([x, y, vx, vy], dim=-1).reshape(-1, 4)


def _classifier(source) -> InitiationClassifier:
    if isinstance(source, OptionBank):
        return source.classifier
    if isinstance(source, InitiationClassifier):
        return source
    bank = getattr(source, "bank", None)  # an agent
    if isinstance(bank, OptionBank):
        return bank.classifier
    raise TypeError(f"expected an InitiationClassifier, an OptionBank or an agent with a bank, "
                    f"got {type(source).__name__}")


@torch.no_grad()
def contains_many(classifier: InitiationClassifier, agent: int, slot: int,
                  obs: Tensor) -> Tensor:
    """``BoolTensor [N]``: membership of ``obs [N, 4]`` in agent ``agent``'s slot ``slot``
    (:meth:`InitiationClassifier.contains_points`)."""
    return classifier.contains_points(agent, slot, obs)


def initiation_density(classifier_or_bank, agent: int = 0, slot: int = 0,
                       resolution: int = 50, velocities=VELOCITIES) -> np.ndarray:
    """The paper's Figure 5 density of an initiation set: ``float64 [resolution, resolution]``.

    Entry ``[j, i]`` is the fraction of the ``len(velocities) ** 2`` velocity pairs (default
    the 25 pairs of ``{-1, -1/2, 0, 1/2, 1}``) for which the observation at the centre of cell
    (column ``i`` = x, row ``j`` = y; y runs downwards as on the board) lies in the set, so
    lightness is proportional to the number of velocity combinations inside it.

    Args:
        classifier_or_bank: an :class:`InitiationClassifier`, an :class:`OptionBank` or an
            agent with a ``bank``.
        agent, slot: which agent's which option.
        resolution: cells per side.
    """
    clf = _classifier(classifier_or_bank)
    if not (0 <= agent < clf.population and 0 <= slot < clf.slots):
        raise ValueError(f"agent {agent}, slot {slot} out of range for P={clf.population}, "
                         f"K={clf.slots}")
    obs = probe_observations(resolution, velocities, dtype=clf.weight.dtype,
                             device=clf.weight.device, dim=clf.obs_dim)
    member = contains_many(clf, agent, slot, obs).reshape(resolution, resolution, -1)
    return member.to(torch.float64).mean(-1).cpu().numpy()


def _board_masks(pinball_map, resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """``(obstacle, target)`` bool ``[R, R]`` masks of the cell centres (row = y)."""
    from skillchain_torch.agents.region_option import inside_obstacle

    centres = (np.arange(resolution) + 0.5) / resolution
    y, x = np.meshgrid(centres, centres, indexing="ij")
    points = torch.as_tensor(np.stack([x.ravel(), y.ravel()], -1), dtype=torch.float64)
    obstacle = inside_obstacle(points, pinball_map).numpy().reshape(resolution, resolution)
    tx, ty = pinball_map.target
    target = (x - tx) ** 2 + (y - ty) ** 2 <= pinball_map.target_radius ** 2
    return obstacle, target


def initiation_image(density: np.ndarray, pinball_map=None, scale: int = 4) -> np.ndarray:
    """``uint8 [R * scale, R * scale, 3]`` (HWC) picture of a density: grey levels = density,
    obstacle cells tinted blue and target cells red when ``pinball_map`` is given."""
    d = np.clip(np.asarray(density, dtype=np.float64), 0.0, 1.0)
    rgb = np.repeat(d[..., None], 3, axis=-1)
    if pinball_map is not None:
        obstacle, target = _board_masks(pinball_map, d.shape[0])
        rgb[obstacle] = 0.5 * rgb[obstacle] + 0.5 * np.array([0.2, 0.35, 0.8])
        rgb[target] = np.array([0.9, 0.1, 0.1])
    image = (rgb * 255.0 + 0.5).astype(np.uint8)
    return np.kron(image, np.ones((scale, scale, 1), dtype=np.uint8)) if scale > 1 else image


def plot_initiation_set(classifier_or_bank, agent: int = 0, slot: int = 0, pinball_map=None,
                        ax=None, resolution: int = 50, cmap: str = "gray", colorbar: bool = False,
                        title: str | None = None):
    """Draw :func:`initiation_density` as an image (with the board's obstacles and target on top
    when ``pinball_map`` is given); returns the matplotlib ``Axes``.

    Example:
        >>> import matplotlib; matplotlib.use("Agg")
        >>> from skillchain_torch.options import InitiationClassifier
        >>> ax = plot_initiation_set(InitiationClassifier(1, 1), resolution=5)
        >>> ax.images[0].get_array().shape
        (5, 5)
    """
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(5, 5))
    density = initiation_density(classifier_or_bank, agent, slot, resolution)
    image = ax.imshow(density, cmap=cmap, vmin=0.0, vmax=1.0, extent=(0.0, 1.0, 1.0, 0.0),
                      origin="upper", interpolation="nearest", zorder=0)
    if pinball_map is not None:
        from skillchain_torch.envs.pinball import plot_trajectories

        plot_trajectories(pinball_map, [], ax=ax, show_starts=False)
        for patch in ax.patches:
            patch.set_alpha(0.6)
    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(1.0, 0.0)
    ax.set_aspect("equal")
    ax.set_title(title if title is not None else f"initiation set: agent {agent}, slot {slot}")
    if colorbar:
        ax.figure.colorbar(image, ax=ax, fraction=0.046, label="fraction of velocities in set")
    return ax


class OptionMonitor:
    """Count option use from a :class:`HierarchicalAgent`'s transitions; log per episode.

    Args:
        logger: a TorchRL logger with ``log_scalar`` and ``experiment`` (a ``SummaryWriter``),
            e.g. :class:`TensorBoardHook`'s; ``None``: count only (read :meth:`end_episodes`).
        probe_resolution: positions per side of the probe grid for ``initiation_size``.
        image_every: write initiation-set images every this many population episodes (also at
            the first and at the end); 0: never.
        image_agents: agents whose options are drawn.
        image_resolution: cells per side of the images.
        per_agent: also write per-agent-episode scalars.
        pinball_map: drawn under the images (default: the trainer's env map).

    Use :meth:`register` with a :class:`PopulationTrainer` (it attaches to ``trainer.agent``),
    or :meth:`attach` an agent yourself and call :meth:`end_episodes` when episodes end.
    Attaching wraps the agent's ``transition`` method (instance attribute; :meth:`detach`
    restores it), because the trainer has no per-step hook.
    """

    def __init__(self, logger=None, probe_resolution: int = 12, image_every: int = 10,
                 image_agents=(0,), image_resolution: int = 50, per_agent: bool = False,
                 pinball_map=None):
        self.logger = logger
        self.probe_resolution = int(probe_resolution)
        self.image_every = int(image_every)
        self.image_agents = tuple(int(p) for p in image_agents)
        self.image_resolution = int(image_resolution)
        self.per_agent = per_agent
        self.pinball_map = pinball_map
        self.agent = None
        self._probe: Tensor | None = None
        self._totals: dict[int, dict[str, np.ndarray]] = {}
        self._last_image = 0

    # ------------------------------------------------------------------ counting
    def attach(self, agent) -> OptionMonitor:
        """Start counting ``agent``'s transitions (it needs ``bank``, ``events``, ``contains``,
        ``max_option_steps`` and ``transition``, as :class:`HierarchicalAgent`)."""
        if self.agent is not None:
            raise RuntimeError("this monitor is already attached to an agent")
        if not isinstance(getattr(agent, "bank", None), OptionBank):
            raise TypeError("the agent has no option bank to monitor")
        self.agent = agent
        P, K = agent.bank.population, agent.bank.slots
        device = agent.bank.status.device
        zeros = dict(dtype=torch.int64, device=device)
        self.steps = torch.zeros(P, **zeros)  # steps of the current episode
        self.option_steps = torch.zeros(P, K, **zeros)
        self.executions = torch.zeros(P, K, **zeros)  # ended executions
        self.execution_steps = torch.zeros(P, K, **zeros)
        self.successes = torch.zeros(P, K, **zeros)
        self.timeouts = torch.zeros(P, K, **zeros)
        self._slots = torch.arange(K, device=device)
        original = agent.transition

        def transition(next_obs, reward, terminated, truncated, stepped):
            info = original(next_obs, reward, terminated, truncated, stepped)
            self._count(info, next_obs, terminated, stepped)
            return info

        self._original = original
        agent.transition = transition
        return self

    def detach(self) -> None:
        """Stop counting (the agent's own ``transition`` is restored)."""
        if self.agent is not None:
            del self.agent.transition  # the instance attribute; the method shows through
            self.agent = None

    @torch.no_grad()
    def _count(self, info: dict, next_obs: Tensor, terminated: Tensor, stepped: Tensor) -> None:
        option = info["option"]
        stepped = stepped.to(torch.bool)
        self.steps += stepped
        under = (option[:, None] == self._slots) & stepped[:, None]  # [P, K]
        self.option_steps += under
        ended = under & info["decision_ended"][:, None]
        if not bool(ended.any()):
            return
        agent = self.agent
        self.executions += ended
        self.execution_steps += ended * info["duration"][:, None]
        reached = info.get("reached")
        if reached is None:  # an agent that does not report its options' targets
            terminated = terminated.to(torch.bool) & stepped
            reached = agent.bank.target_reached(next_obs, terminated, agent.events,
                                                contains=agent.contains)
        success = ended & reached
        self.successes += success
        timeout = ended & ~reached & (info["duration"][:, None] >= agent.max_option_steps)
        self.timeouts += timeout

    _COUNTERS = ("steps", "option_steps", "executions", "execution_steps", "successes",
                 "timeouts")

    def counts(self, agents=None) -> dict[str, np.ndarray]:
        """The current (unfinished episode) counters of ``agents`` (default all) as numpy."""
        index = slice(None) if agents is None else torch.as_tensor(agents, dtype=torch.int64)
        return {name: getattr(self, name)[index].cpu().numpy() for name in self._COUNTERS}

    def end_episodes(self, agents, episodes) -> dict[str, np.ndarray]:
        """Fold the counters of ``agents`` (their episodes ``episodes``, 0-based) into the
        episode totals, reset them, and return their per-agent counts."""
        index = torch.as_tensor(list(agents), dtype=torch.int64,
                                device=self.steps.device)
        counts = self.counts(index)
        for name in self._COUNTERS:
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
        (NaN for empty slots)."""
        bank = self.agent.bank
        clf = bank.classifier
        if self._probe is None:
            self._probe = probe_observations(self.probe_resolution, dtype=clf.weight.dtype,
                                             dim=clf.obs_dim,
                                             device=clf.weight.device)
        live = bank.live().cpu().numpy()
        out = np.full(live.shape, np.nan)
        for p, k in zip(*np.nonzero(live)):
            out[p, k] = float(contains_many(clf, p, k, self._probe).to(torch.float64).mean())
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
        counts = self.end_episodes(batch.agents, batch.episodes)
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
        sizes = self.initiation_sizes()
        log("options/primitive_step_share", float(stats["primitive_step_share"]), step=episode)
        log("options/live_slots", float(live.sum(-1).mean()), step=episode)
        for k in np.nonzero(live.any(0))[0]:
            prefix = f"options/slot_{k}"
            log(f"{prefix}/step_share", float(stats["step_share"][k]), step=episode)
            log(f"{prefix}/executions", float(stats["executions"][k]), step=episode)
            for key in ("mean_duration", "success_rate", "timeout_rate"):
                if np.isfinite(stats[key][k]):
                    log(f"{prefix}/{key}", float(stats[key][k]), step=episode)
            log(f"{prefix}/initiation_size", float(np.nanmean(sizes[:, k])), step=episode)

    def log_images(self, episode: int) -> None:
        """Write the Figure-5 initiation-set images of ``image_agents``' live slots."""
        self._last_image = episode
        live = self.agent.bank.live().cpu().numpy()
        for p in self.image_agents:
            if p >= live.shape[0]:
                continue
            for k in np.nonzero(live[p])[0]:
                density = initiation_density(self.agent.bank, p, int(k), self.image_resolution)
                image = initiation_image(density, self.pinball_map)
                self.logger.experiment.add_image(f"options/initiation/agent_{p}/slot_{k}", image,
                                                 episode, dataformats="HWC")

    def post_train(self, trainer) -> None:
        if self.logger is None:
            return
        episode = int(trainer.episodes_done.min())
        if self.image_every > 0 and episode > self._last_image:
            self.log_images(episode)
        self.logger.experiment.flush()


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
