"""``PopulationTrainer``: P independent agents, one Pinball environment each, E episodes each.

The loop reads top to bottom (``train``): iterate the
:class:`~skillchain_torch.collectors.HierarchicalCollector`, which steps the active
environments, lets the agents learn and act, and restarts or retires agents whose episodes
ended; it hands over a ``TensorDict`` batch ``[T, n]`` at every step in which episodes ended,
and the trainer records those episodes, checks the learners, runs the hooks and writes
checkpoints. Agent ``p`` of a population seeded ``S`` is bit-identical to a single run
seeded ``S + p``: its decisions come from its own counter-based stream, its env from its own
start stream, and every tensor operation is row-independent (no reduction across agents).

Why not ``torchrl.trainers.Trainer``: it assumes one loss module optimised by a torch optimizer
over a fixed parameter set, fed by a collector yielding fixed-size batches to learn from. Here
updates are closed-form TD steps applied on every environment step, inside the collector's
step, agents finish their episodes at different times (the batch shrinks), and skill chaining
spawns options, so an agent's parameter set grows during training. The class keeps TorchRL's
conventions instead: hooks registered by stage and name (``register_op``), stateful
components registered with ``register_module`` and saved with the trainer, a TorchRL logger
(:class:`~.logging.TensorBoardHook`), and ``state_dict``/``load_state_dict`` for checkpoints.

Hook stages: ``"pre_train"`` ``op(trainer)``; ``"post_episodes"`` ``op(trainer, batch)`` after a
step in which episodes ended (an :class:`EpisodeBatch`, with the collector's batch as
``transitions``); ``"post_checkpoint"``
``op(trainer, path)``; ``"post_train"`` ``op(trainer)`` once every agent has finished.

Checkpoints: whenever the slowest agent completes a multiple of ``checkpoint_every`` episodes
(``min`` over agents of episodes completed), and at the end, to
``out_dir/checkpoints/ckpt_{episodes:06d}.pt``.

Divergence: at each episode end the learners of the agents whose episodes ended (the top-level
Q-head, and for agents with options the option Q-heads and the initiation classifiers) are
checked for NaN or infinite weights, and every learner of every agent before each checkpoint
is written. A diverged run stops with :class:`Diverged` (a ``FloatingPointError`` naming the
agents, the learner and the parameter to change); it writes no checkpoint of the diverged
weights, so the last one written is good, and saves the returns so far as
``out_dir/partial_returns.npy`` and ``partial_lengths.npy`` with ``out_dir/diverged.json``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDict

from skillchain_torch.collectors import HierarchicalCollector
from skillchain_torch.envs.classic import batched_stepper
from skillchain_torch.envs.external import make_env, read_specs
from skillchain_torch.envs.pinball import PinballEnv
from skillchain_torch.envs.pinball.stepper import ActiveEnvStepper
from skillchain_torch.policies import LinearEpsilon
from skillchain_torch.trainers.config.config import TrainConfig
from skillchain_torch.trainers.config.registry import make_agent
from skillchain_torch.trainers.loop.env_stepper import EnvStepper
from skillchain_torch.trainers.loop.user_agent import agent_label, check_agent, run_record

__all__ = ["PopulationTrainer", "EpisodeBatch", "STAGES", "Diverged", "DIVERGED_OUTPUTS"]

STAGES = ("pre_train", "post_episodes", "post_checkpoint", "post_train")
DIVERGED_OUTPUTS = ("diverged.json", "partial_returns.npy", "partial_lengths.npy")


@dataclass(frozen=True)
class EpisodeBatch:
    """Episodes that ended in one step (parallel lists), and the population's progress.

    ``episodes`` are 0-based indices into the agents' episode axis. ``population_episode`` is
    the 1-based episode that every agent has now completed, when this step completed it for
    the slowest agent (else ``None``).
    """

    agents: list[int]
    episodes: list[int]
    returns: list[float]
    lengths: list[int]
    terminated: list[bool]
    population_episode: int | None
    #: the collector's batch that ended with these episodes (``[T, n]``, the steps since the
    #: previous batch: every active agent's transitions), for hooks that read transitions
    transitions: TensorDict | None = None


def with_env_sizes(config: TrainConfig, sizes=None) -> TrainConfig:
    """``config`` with ``obs_dim`` and ``num_actions`` read from its env's specs (Pinball's
    config is returned as it is). ``ValueError`` (one line) for an env that cannot be made or
    whose specs do not fit."""
    if config.env is None:
        return config
    if sizes is None:
        sizes = read_specs(make_env(config.env), config.obs_bounds)
    return dataclasses.replace(config, obs_dim=sizes.obs_dim, num_actions=sizes.num_actions)


class Diverged(FloatingPointError):
    """A learner's weights became NaN or infinite, so the run stopped.

    ``agents``: the diverged agents' ids; ``learners``: ``{learner: [agent ids]}``. The
    message (one line) names them and the run parameter to change.
    """

    def __init__(self, message: str, agents: list[int], learners: dict[str, list[int]]):
        super().__init__(message)
        self.agents, self.learners = agents, learners


def _per_agent(module, population: int, names: tuple[str, ...] = ("weight",)) -> list:
    """A learner's tensors to check for divergence, each ``[P, ...]``: the built-in
    ``names`` where the module has them, and the trainable parameters of a user's model that
    hold one slice per agent (a parameter shared by all agents cannot be told apart by agent
    and is not checked)."""
    tensors = [getattr(module, n) for n in names if isinstance(getattr(module, n, None),
                                                               torch.Tensor)]  # fmt: skip
    seen = {id(t) for t in tensors}
    parameters = module.parameters() if hasattr(module, "parameters") else ()
    tensors += [p for p in parameters if p.requires_grad and id(p) not in seen
                and p.dim() >= 1 and p.shape[0] == population]  # fmt: skip
    return [t.detach() for t in tensors]


def _widened(saved: np.ndarray, episodes: int, fill) -> np.ndarray:
    """``saved [P, E, ...]`` with room for ``episodes >= E`` (``fill`` after E): a run
    extended by ``--resume --episodes`` continues into the new columns."""
    if saved.shape[1] >= episodes:
        return saved.copy()
    out = np.full((saved.shape[0], episodes, *saved.shape[2:]), fill, dtype=saved.dtype)
    out[:, :saved.shape[1]] = saved
    return out


def _short(values: list[int], most: int = 10) -> str:
    """``[0, 1, 2]``, or the first ``most`` and how many in all."""
    if len(values) <= most:
        return str(values)
    return f"[{', '.join(map(str, values[:most]))}, ... ({len(values)} in all)]"


class PopulationTrainer:
    """Train a population of agents on Pinball.

    Args:
        config: the run (validated; ``order``/``alpha`` resolved to the paper's values).
        out_dir: where checkpoints go (``out_dir/checkpoints``); ``None``: no checkpoints.
        native: the compiled code (default: when built, on the CPU): the Pinball step, which
            gives the same bits as its tensor path (:class:`ActiveEnvStepper`), and the flat
            agent's kernels, which agree with its torch path to rounding
            (:class:`~skillchain_torch.agents.FlatSarsaAgent`). ``False`` runs torch and Python
            only.
        num_threads: torch intra-op threads while :meth:`train` runs (restored afterwards);
            ``None`` keeps torch's setting. Default 1: the per-step tensors are small, and a
            parallel region waits for a busy core (10x slowdowns on a shared machine).
        agent: an agent object of your own composition (``config.runs`` agents, the episode
            protocol of :class:`~skillchain_torch.agents.FlatSarsaAgent`, e.g. a
            :class:`~skillchain_torch.agents.SkillChainingAgent` with your own pieces);
            ``None`` builds ``config.agent`` by name.
        batched_envs: off Pinball, step the population's envs in one call where the env has
            a batched stepper (:func:`~skillchain_torch.envs.classic.batched_stepper`:
            MountainCar, the same numbers as Gymnasium's); ``False`` steps one ``GymEnv`` per
            agent whatever the env.

    Example:
        >>> trainer = PopulationTrainer(TrainConfig(runs=2, episodes=1, max_episode_steps=5))
        >>> trainer.train().returns.shape
        (2, 1)
        >>> trainer.lengths.tolist()
        [[5], [5]]
    """

    def __init__(self, config: TrainConfig, out_dir: str | Path | None = None,
                 num_threads: int | None = 1, native: bool | None = None, agent=None,
                 batched_envs: bool = True):
        if config.env is not None:  # the env's sizes from its specs, before the defaults
            first = make_env(config.env)
            sizes = read_specs(first, config.obs_bounds)
            config = with_env_sizes(config, sizes)
        config = config.resolved().validate()
        self.config = config
        self.out_dir = None if out_dir is None else Path(out_dir)
        self.num_threads = num_threads
        self.device = torch.device(config.device)
        if config.env is None:
            self.env = PinballEnv(config.map, batch_size=[config.runs], device=self.device,
                                  dtype=torch.float64, max_episode_steps=config.max_episode_steps,
                                  seed=config.seed)  # fmt: skip
            self.stepper = ActiveEnvStepper(self.env, native=native)
        else:  # the env's own batched stepper where it has one, else one GymEnv per agent
            batched = batched_stepper(config.env, config.runs, sizes, seed=config.seed,
                                      max_episode_steps=config.max_episode_steps)
            if batched is not None and batched_envs:
                self.env, self.stepper = None, batched
            else:
                self.env = [first] + [make_env(config.env) for _ in range(config.runs - 1)]
                self.stepper = EnvStepper(self.env, sizes, seed=config.seed,
                                          max_episode_steps=config.max_episode_steps)
        self.user_agent = agent is not None  # built by the user: config.json says so
        if agent is None:
            agent = make_agent(config, device=self.device, native=native)
        else:
            check_agent(agent, config)
        # Any agent may anneal its exploration through set_epsilon (neural heads need it);
        # agents step once per population step while active, so the schedule reads global_step.
        self._epsilon = (None if config.epsilon_init is None else LinearEpsilon(
            config.epsilon_init, config.epsilon, config.annealing_steps))  # fmt: skip
        # The loop: the collector steps the envs and the agents, and hands over a batch at
        # every step in which episodes ended (records, hooks and checkpoints go between).
        self.collector = HierarchicalCollector(self.stepper, agent, episodes=config.episodes,
                                               epsilon=self._epsilon, state=False)
        bank = getattr(self.agent, "bank", None)
        if bank is not None:
            bank.learned_on(config.env_name)  # saved with the options (another env refuses them)
        self.diverged: Diverged | None = None
        P, E = config.runs, config.episodes
        self.returns = np.full((P, E), np.nan)
        self.lengths = np.zeros((P, E), dtype=np.int64)
        self.elapsed = 0.0  # wall seconds spent in train(), over resumes
        self._finalized = False
        self._clock = time.perf_counter()
        self._training = False
        self._next_checkpoint = config.checkpoint_every or None
        self._checkpoint_wall = 0.0  # wall_time at the last checkpoint (checkpoint_minutes)
        self._written: list[Path] = []  # checkpoints this process wrote, oldest first
        self._anchor: Path | None = None  # the newest of them written before any agent finished
        self._ops: dict[str, list[tuple[str, object]]] = {stage: [] for stage in STAGES}
        self._modules: dict[str, object] = {}
        self._pending_modules: dict[str, dict] = {}  # loaded before their module registered
        self._anneal()

    @property
    def agent(self):
        """The agents the collector drives (assigning one replaces them there too)."""
        return self.collector.agent

    @agent.setter
    def agent(self, agent) -> None:
        self.collector.agent = agent

    # The loop's progress lives in the collector (declared once); the trainer reads it.
    @property
    def global_step(self) -> int:
        """Population steps so far (every active agent steps once per population step)."""
        return self.collector.global_step

    @property
    def agent_steps(self) -> int:
        """Environment steps summed over agents (the collector's frames)."""
        return self.collector.frames

    @property
    def episodes_done(self) -> np.ndarray:
        """Episodes each agent has completed ``[P]`` (a view of the collector's count)."""
        return self.collector.episodes_done.numpy()

    @property
    def started(self) -> bool:
        return self.collector.started

    def _anneal(self) -> None:
        """The top level's epsilon at ``global_step`` (where the config anneals it)."""
        if self._epsilon is not None:
            self.agent.set_epsilon(self._epsilon(self.global_step))

    # ------------------------------------------------------------------ hooks
    def register_op(self, stage: str, op, name: str | None = None) -> None:
        """Call ``op`` at ``stage`` (one of ``STAGES``); ``name`` must be unique per stage."""
        if stage not in self._ops:
            raise ValueError(f"unknown hook stage {stage!r}; stages: {', '.join(STAGES)}")
        name = name or getattr(op, "__name__", type(op).__name__)
        if any(n == name for n, _ in self._ops[stage]):
            raise ValueError(f"a hook named {name!r} is already registered at {stage!r}")
        self._ops[stage].append((name, op))

    def register_module(self, name: str, module) -> None:
        """Save ``module.state_dict()`` with the trainer's checkpoints under ``name`` (and
        restore it, when a loaded checkpoint holds that name, even if loaded earlier)."""
        if name in self._modules:
            raise RuntimeError(f"{name} is already registered, choose a different name.")
        self._modules[name] = module
        if name in self._pending_modules:  # registered after a checkpoint was loaded
            module.load_state_dict(self._pending_modules.pop(name))

    def _call(self, stage: str, *args) -> None:
        for _, op in self._ops[stage]:
            op(self, *args)

    # ------------------------------------------------------------------ loop
    @property
    def num_active(self) -> int:
        return self.collector.num_active

    @property
    def finished(self) -> bool:
        return self.collector.finished

    def train(self, max_agent_steps: int | None = None) -> PopulationTrainer:
        """Run until every agent has finished its episodes (or ``agent_steps`` reaches
        ``max_agent_steps``; calling ``train`` again continues)."""
        if self.diverged is not None:
            raise self.diverged
        self._clock = time.perf_counter()
        self._training = True
        threads = torch.get_num_threads()
        if self.num_threads is not None:
            torch.set_num_threads(self.num_threads)
        try:
            try:
                if not self.started:
                    self.collector.start()
                self._call("pre_train")
                self.collector.max_frames = max_agent_steps
                for batch in self.collector:  # a batch ends where episodes end, or at the limit
                    if bool(batch.get(("next", "done"))[-1].any()):
                        self._episode_ends(batch)
            finally:
                self._tick()
                self._training = False
                torch.set_num_threads(threads)
            if self.finished and not self._finalized:
                self._finalized = True
                self._finish()
        except FloatingPointError as error:  # ours, or the flat agent's own check
            raise self._diverge(error) from None
        return self

    def _tick(self) -> None:
        now = time.perf_counter()
        self.elapsed += now - self._clock
        self._clock = now

    def _episode_ends(self, batch) -> None:
        """Record the episodes that ended at the batch's last step, check those agents'
        learners, run the ``post_episodes`` hooks and write a checkpoint when one is due (the
        collector has restarted or retired the agents already)."""
        nxt = batch.get("next")
        done = nxt.get("done")[-1, :, 0]  # (the leaves' last step: no TensorDict indexing)
        ids = batch.get("agent")[-1][done]
        agents = ids.tolist()
        returns = nxt.get("episode_reward")[-1, done, 0].tolist()
        lengths = nxt.get("step_count")[-1, done, 0].tolist()
        term = nxt.get("terminated")[-1, done, 0].tolist()
        episodes_done = self.episodes_done
        episodes = (episodes_done[agents] - 1).tolist()  # (the collector counted them)
        before_done = episodes_done.copy()
        before_done[agents] -= 1
        before = int(before_done.min())
        self.returns[agents, episodes] = returns
        self.lengths[agents, episodes] = lengths
        self.check_learners(ids)
        after = int(episodes_done.min())
        episode_batch = EpisodeBatch(agents, episodes, returns, lengths, term,
                                     after if after > before else None, batch)
        self._call("post_episodes", episode_batch)
        minutes = self.config.checkpoint_minutes
        if self._next_checkpoint is not None and after >= self._next_checkpoint:
            self._next_checkpoint = after + self.config.checkpoint_every
            if self.num_active > 0 and self.out_dir is not None:
                self._tick()
                self.save_checkpoint()
        elif (minutes and self.num_active > 0 and self.out_dir is not None
              and self.wall_time - self._checkpoint_wall >= 60.0 * minutes):  # fmt: skip
            # by the clock (between steps, as the episode checkpoints): no bit depends on it
            self._tick()
            self.save_checkpoint()

    def _finish(self) -> None:
        self.stepper.sync()
        self.agent.flush()
        if self.out_dir is not None:
            self.save_checkpoint()
        self._call("post_train")

    # ------------------------------------------------------------------ outputs
    @property
    def weights(self) -> torch.Tensor:
        """The agents' Q weights ``[P, D, F]`` (working rows flushed first)."""
        self.agent.flush()
        return self.agent.q_head.weight

    @property
    def wall_time(self) -> float:
        """Seconds spent in :meth:`train` so far (over resumes), up to this moment."""
        return self.elapsed + (time.perf_counter() - self._clock if self._training else 0.0)

    def steps_per_second(self) -> float:
        """Agent steps per second of :meth:`train` time (environment, decisions and updates)."""
        wall = self.wall_time
        return self.agent_steps / wall if wall > 0 else 0.0

    def checkpoint_path(self, episodes: int | None = None) -> Path:
        if self.out_dir is None:
            raise ValueError("this trainer has no out_dir, so it writes no checkpoints")
        episodes = int(self.episodes_done.min()) if episodes is None else episodes
        return self.out_dir / "checkpoints" / f"ckpt_{episodes:06d}.pt"

    def save_checkpoint(self, path: str | Path | None = None) -> Path:
        from skillchain_torch.trainers.outputs.checkpoint import save_checkpoint

        path = self.checkpoint_path() if path is None else Path(path)
        self.check_learners()  # never a checkpoint of diverged weights
        save_checkpoint(self, path)
        self._checkpoint_wall = self.wall_time
        self._prune_checkpoints(path)
        self._call("post_checkpoint", path)
        return path

    def _prune_checkpoints(self, newest: Path) -> None:
        """With ``keep_checkpoints`` N > 0, delete this process's older checkpoints but the
        newest N and the newest written while no agent had finished (the one ``--resume
        --episodes`` extends a run from). Files this process did not write are never touched,
        so a resumed run keeps whatever the earlier processes left."""
        if newest not in self._written:
            self._written.append(newest)
        if int(self.episodes_done.max()) < self.config.episodes:
            self._anchor = newest
        keep = self.config.keep_checkpoints
        if not keep:
            return
        drop = [p for p in self._written[:-keep] if p != self._anchor]
        for old in drop:
            old.unlink(missing_ok=True)
        self._written = [p for p in self._written if p not in drop]

    def write_results(self, out_dir: str | Path | None = None) -> None:
        """``returns.npy`` (float64 [P, E]), ``lengths.npy`` (int64) and ``config.json`` (for
        an agent of your own, its agent fields ``null``: :func:`.user_agent.recorded_config`).
        ``skillchain_torch.trainers.train_and_write`` writes every output the CLI writes."""
        out = Path(out_dir) if out_dir is not None else self.out_dir
        out.mkdir(parents=True, exist_ok=True)
        np.save(out / "returns.npy", self.returns)
        np.save(out / "lengths.npy", self.lengths)
        (out / "config.json").write_text(json.dumps(run_record(self), indent=2) + "\n")

    # ------------------------------------------------------------------ state
    def state_dict(self) -> dict:
        loop = self.collector.state_dict()
        return {
            "config": self.config.to_dict(),
            "agent": self.agent.state_dict(),
            "env": self.stepper.state_dict(),
            "trainer": {
                "returns": torch.from_numpy(self.returns.copy()),
                "lengths": torch.from_numpy(self.lengths.copy()),
                "episodes_done": loop["episodes_done"],
                "partial_return": loop["partial_return"],
                "partial_length": loop["partial_length"],
                "global_step": loop["global_step"],
                "agent_steps": loop["agent_steps"],
                "elapsed": self.elapsed,
                "started": loop["started"],
                "next_checkpoint": self._next_checkpoint,
                "user_agent": self.user_agent,  # its agent section is what the agent declares
            },
            "modules": {name: m.state_dict() for name, m in self._modules.items()},
        }

    def load_state_dict(self, state: dict) -> None:
        t = state["trainer"]
        self.agent.load_state_dict(state["agent"])
        self.stepper.load_state_dict(state["env"])
        self.returns = _widened(t["returns"].numpy(), self.config.episodes, np.nan)
        self.lengths = _widened(t["lengths"].numpy(), self.config.episodes, 0)
        self.collector.load_state_dict(t)
        self._anneal()
        self.elapsed = float(t["elapsed"])
        self._finalized = False
        self._next_checkpoint = t["next_checkpoint"]
        self._checkpoint_wall = self.elapsed  # (the clock restarts from the loaded run's)
        self._pending_modules = {}
        for name, saved in state["modules"].items():
            if name in self._modules:
                self._modules[name].load_state_dict(saved)
            else:
                self._pending_modules[name] = saved

    def __repr__(self) -> str:
        c = self.config
        return (f"PopulationTrainer(agent={agent_label(self)!r}, env={c.env_name!r}, "
                f"runs={c.runs}, episodes={c.episodes}, seed={c.seed}, active={self.num_active})")

    # ------------------------------------------------------------------ divergence
    def _learners(self, agents: torch.Tensor | None) -> list[tuple[str, str, list[torch.Tensor]]]:
        """``(learner, advice, tensors)`` with agents on dim 0: the learners of the agents
        ``agents`` (ids, ascending; ``None``: all P agents, after a flush)."""
        agent, cfg = self.agent, self.config
        rows = None
        if agents is None:
            agent.flush()
            ids = None
        else:
            index = agent.index
            found = torch.searchsorted(index, agents.to(index.device)).clamp(
                max=max(index.numel() - 1, 0))  # fmt: skip
            if index.numel() and bool((index[found] == agents.to(index.device)).all()):
                rows = found  # all still active: the compact rows of their ids
            ids = int(agents[0]) if agents.numel() == 1 else agents  # (one: views, no copies)

        def pick(t: torch.Tensor) -> torch.Tensor:
            if ids is None:
                return t
            if isinstance(ids, int):
                return t[ids:ids + 1]
            return t.index_select(0, ids.to(t.device))

        working = getattr(agent, "working_weights", None)  # the flat agent's, without a flush
        if rows is not None and working is not None:
            top = working(rows)
        elif agents is not None and working is not None:  # some just retired (and flushed)
            agent.flush()
            top = [pick(t) for t in _per_agent(agent.q_head, agent.population)]
        elif getattr(agent, "q_head", None) is None:  # an agent of the protocol alone
            top = []  # (EpisodeAgent declares no head; nothing the trainer can check)
        else:
            top = [pick(t) for t in _per_agent(agent.q_head, agent.population)]
        learners = [("the top-level Q-head", f"lower --alpha (now {cfg.alpha:g})",
                     top if isinstance(top, list) else [top])]
        bank = getattr(agent, "bank", None)
        if bank is None:
            return self._for_user(learners)
        heads = [pick(t) for t in bank.q_head.slot_tensors().values()]  # [P, K, ...]
        alpha = bank.q_head.config.get("alpha")
        if cfg.agent == "given-options":
            advice = (f"their step size (alpha {alpha:g}) is the one saved in --options "
                      f"{cfg.options}" if alpha is not None else "")
        elif cfg.option_alpha == 0:  # they never learn: a joining option copies the top level
            advice = f"they only copy the top-level Q-head: lower --alpha (now {cfg.alpha:g})"
        else:
            advice = f"lower --option-alpha (now {cfg.option_alpha:g})"
        classifier = bank.classifier
        learners += [
            ("the option Q-heads", advice, heads),
            ("the initiation classifiers",
             f"their step size (lr {classifier.lr:g}) is not a run parameter"
             if isinstance(getattr(classifier, "lr", None), float) else "",
             [pick(t) for t in _per_agent(classifier, agent.population, ("weight", "bias"))]),
        ]
        return self._for_user(learners)

    def _for_user(self, learners: list) -> list:
        """The advice for an agent built in Python, whose step sizes no flag set."""
        if not getattr(self, "user_agent", False):
            return learners
        return [(name, "lower its step size where you built the agent", tensors)
                for name, _, tensors in learners]  # fmt: skip

    def check_learners(self, agents: torch.Tensor | None = None) -> None:
        """Raise :class:`Diverged` if a learner of the agents ``agents`` (ids; default: every
        agent) holds a NaN or infinite weight. One reduction per tensor and one sync when all
        is well."""
        learners = self._learners(agents)
        # A sum is non-finite if any term is (an overflowing sum of finite weights is looked
        # at below and passes).
        sums = [t.sum() for _, _, tensors in learners for t in tensors]
        if not sums or math.isfinite(torch.stack(sums).sum()):
            return
        ids = (torch.arange(self.config.runs) if agents is None else agents).tolist()
        found: dict[str, list[int]] = {}
        parts = []
        for learner, advice, tensors in learners:
            bad = torch.zeros(len(ids), dtype=torch.bool)
            for t in tensors:
                bad |= ~torch.isfinite(t.reshape(len(ids), -1)).all(-1).cpu()
            if bool(bad.any()):
                found[learner] = [ids[i] for i in bad.nonzero().flatten().tolist()]
                parts.append(f"{learner} of agents {_short(found[learner])}"
                             + (f": {advice}" if advice else ""))
        if not found:
            return
        agents = sorted({a for group in found.values() for a in group})
        done = sorted({int(self.episodes_done[a]) for a in agents})
        done_text = str(done[0]) if len(done) == 1 else f"{done[0]}-{done[-1]}"
        last = None
        if self.out_dir is not None:
            from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint

            last = latest_checkpoint(self.out_dir)
        saved = (f"returns so far in {self.out_dir / 'partial_returns.npy'}; last good "
                 f"checkpoint {last if last is not None else 'none (none was written yet)'}"
                 if self.out_dir is not None else "no out_dir, nothing saved")
        raise Diverged(
            f"agents {_short(agents)} have non-finite weights (NaN or infinite) after "
            f"{done_text} completed episodes: " + "; ".join(parts)
            + f". The run diverged and stopped: {saved}", agents, found)

    def _diverge(self, error: FloatingPointError) -> FloatingPointError:
        """The :class:`Diverged` for ``error`` (the flat agent's own check names no learner:
        every learner is checked), after saving the returns so far; ``error`` itself if no
        learner is non-finite."""
        if not isinstance(error, Diverged):
            try:
                self.check_learners()
                return error
            except Diverged as found:
                error = found
        self.diverged = error
        if self.out_dir is not None:
            out = self.out_dir
            out.mkdir(parents=True, exist_ok=True)
            np.save(out / "partial_returns.npy", self.returns)
            np.save(out / "partial_lengths.npy", self.lengths)
            info = {"error": str(error), "agents": error.agents, "learners": error.learners,
                    "episodes_done": self.episodes_done.tolist(),
                    "config": run_record(self)}
            (out / "diverged.json").write_text(json.dumps(info, indent=1) + "\n")
        return error
