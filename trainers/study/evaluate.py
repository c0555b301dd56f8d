"""Evaluate a trained run: load its agents, run greedy episodes, draw one agent's episodes.

``skillchain eval RUN_DIR --episodes N`` and :func:`evaluate` in Python. :func:`load_run`
rebuilds a run's config and agents from ``RUN_DIR/config.json`` and its last checkpoint. The
evaluation freezes them: no learning, no discovery, no refits (a skill-chaining agent becomes a
plain :class:`~skillchain_torch.agents.HierarchicalAgent` over its options, as the paper's
Figure 4b replays do), explores at ``epsilon`` (default 0: greedy), and runs ``episodes``
episodes per agent, all agents as one population, each episode cut at ``max_steps`` (a greedy
agent can circle forever). Its streams are its own (``seed``, default the run's seed plus
1,000,000), so an evaluation never replays the training's random numbers.

Example:
    >>> import tempfile
    >>> from skillchain_torch.trainers import PopulationTrainer, TrainConfig
    >>> out = tempfile.mkdtemp()
    >>> config = TrainConfig(agent="flat", map="pinball_box", runs=2, episodes=2,
    ...                      max_episode_steps=200)
    >>> config.save_json(f"{out}/config.json")
    >>> _ = PopulationTrainer(config, out_dir=out).train()
    >>> run = load_run(out)
    >>> run.config.runs, type(run.agent).__name__
    (2, 'FlatSarsaAgent')
    >>> result = evaluate(run, episodes=3, max_steps=100)
    >>> result.returns.shape
    (2, 3)
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from skillchain_torch.trainers.config.config import TrainConfig
from skillchain_torch.trainers.study.intervals import mean_ci

__all__ = ["Run", "Evaluation", "load_run", "evaluate", "frozen_agent", "render_episodes",
           "EVAL_SEED_OFFSET"]

EVAL_SEED_OFFSET = 1_000_000  # an evaluation's streams: the run's seed plus this, by default


@dataclass
class Run:
    """A finished (or interrupted) run: its directory, config, agents and the checkpoint read."""

    dir: Path
    config: TrainConfig
    agent: object
    checkpoint: Path


@dataclass
class Evaluation:
    """Returns and lengths ``[P, N]`` of N evaluation episodes per agent."""

    returns: np.ndarray
    lengths: np.ndarray
    epsilon: float
    max_steps: int
    seed: int

    def table(self) -> str:
        """Per-agent means, then the mean over agents with its 95% t interval."""
        lines = ["| agent | mean return | episodes reaching the cap |", "|---:|---:|---:|"]
        for p, (r, n) in enumerate(zip(self.returns, self.lengths)):
            lines.append(f"| {p} | {r.mean():,.1f} | {int((n >= self.max_steps).sum())} |")
        mean, half = mean_ci(self.returns.mean(axis=1))
        half_text = "n/a (one agent)" if np.isnan(half) else f"{half:,.1f}"
        lines.append(f"\nmean over {self.returns.shape[0]} agents: {mean:,.1f} +- {half_text} "
                     f"(95% t interval), {self.returns.shape[1]} episodes each, epsilon "
                     f"{self.epsilon:g}, at most {self.max_steps:,} steps per episode")
        return "\n".join(lines)


def load_run(run_dir: str | Path, device: str | None = None) -> Run:
    """The run in ``run_dir``: its ``config.json`` and its agents as of its last good
    checkpoint. ``ValueError`` in one line for a folder without them (the committed studies
    keep arrays and figures, not checkpoints).

    Example: ``run = load_run("runs/demo"); run.agent.q_head.weight.shape``.
    """
    from skillchain_torch.trainers.loop.population import PopulationTrainer
    from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint, resume_checkpoint

    run_dir = Path(run_dir)
    if not (run_dir / "config.json").is_file():
        raise ValueError(f"{run_dir}: no config.json there (not a run directory)")
    config = TrainConfig.load_json(run_dir / "config.json")
    if str(config.agent).startswith("user:"):
        raise ValueError(f"{run_dir}: its agent was the user's own ({config.agent}); load it "
                         "with your own code and trainer.load_checkpoint")  # fmt: skip
    if latest_checkpoint(run_dir) is None:
        raise ValueError(f"{run_dir}: no checkpoint under {run_dir / 'checkpoints'} (this run "
                         "kept its arrays and figures only), so its agents cannot be loaded; "
                         "train it again with --out to evaluate it")  # fmt: skip
    if device is not None:
        config = dataclasses.replace(config, device=device)
    trainer = PopulationTrainer(config)
    checkpoint = resume_checkpoint(run_dir, trainer)
    if hasattr(trainer.agent, "flush"):
        trainer.agent.flush()
    return Run(run_dir, trainer.config, trainer.agent, checkpoint)


def frozen_agent(run: Run, epsilon: float, seed: int, rows: list[int] | None = None):
    """A copy of ``run``'s agents ``rows`` (default all) that acts (``epsilon``-greedy, row i
    drawing from its own stream ``seed + i``) and never learns: a flat agent with step size 0,
    a hierarchical one as a plain :class:`~skillchain_torch.agents.HierarchicalAgent` over its
    options (no discovery)."""
    from skillchain_torch.agents import FlatSarsaAgent, HierarchicalAgent
    from skillchain_torch.trainers.outputs.option_trajectory import _frozen_agents

    agent, config = run.agent, run.config
    rows = list(range(config.runs)) if rows is None else [int(p) for p in rows]
    if isinstance(agent, HierarchicalAgent):
        return _frozen_agents(agent, rows, epsilon, [seed + i for i in range(len(rows))])
    if isinstance(agent, FlatSarsaAgent):
        frozen = FlatSarsaAgent(dataclasses.replace(config, runs=len(rows), epsilon=epsilon,
                                                    seed=seed))  # fmt: skip
        with torch.no_grad():
            frozen.q_head.weight.copy_(agent.q_head.weight[rows])
            frozen.update.step_size.zero_()  # acts, never learns
        frozen._set_active(torch.arange(len(rows), device=frozen.q_head.weight.device))
        return frozen
    raise TypeError(f"cannot evaluate a {type(agent).__name__}: eval knows the flat agent and "
                    "the hierarchical agents")  # fmt: skip


def evaluate(run: Run, episodes: int = 10, epsilon: float = 0.0, max_steps: int = 10_000,
             seed: int | None = None, quiet: bool = True) -> Evaluation:  # fmt: skip
    """``episodes`` frozen episodes of every agent of ``run`` (see the module docstring)."""
    from skillchain_torch.trainers.loop.population import PopulationTrainer

    if episodes < 1 or max_steps < 1 or not 0.0 <= epsilon <= 1.0:
        raise ValueError(f"need episodes >= 1, max_steps >= 1 and epsilon in [0, 1], got "
                         f"{episodes}, {max_steps}, {epsilon}")  # fmt: skip
    seed = run.config.seed + EVAL_SEED_OFFSET if seed is None else int(seed)
    config = dataclasses.replace(run.config, episodes=episodes, max_episode_steps=max_steps,
                                 seed=seed, epsilon=epsilon, epsilon_init=None,
                                 annealing_steps=0)  # fmt: skip
    trainer = PopulationTrainer(config, agent=frozen_agent(run, epsilon, seed))
    if not quiet:
        from skillchain_torch.trainers.outputs.progress import ProgressBar

        ProgressBar().register(trainer)
    trainer.train()
    return Evaluation(np.asarray(trainer.returns), np.asarray(trainer.lengths), epsilon,
                      max_steps, seed)  # fmt: skip


def render_episodes(run: Run, path: str | Path, agent_index: int = 0, episodes: int = 1,
                    epsilon: float = 0.0, max_steps: int = 10_000, seed: int | None = None,
                    fps: int = 30, every: int = 2) -> Path:  # fmt: skip
    """A GIF of agent ``agent_index``'s frozen episodes (every ``every``-th step a frame):
    Pinball's own renderer, or a Gymnasium env's ``rgb_array`` frames."""
    from PIL import Image

    config = run.config
    if not 0 <= agent_index < config.runs:
        raise ValueError(f"--agent-index must be in [0, {config.runs - 1}], got {agent_index}")
    seed = config.seed + EVAL_SEED_OFFSET if seed is None else int(seed)
    frames: list[np.ndarray] = []
    for episode in range(episodes):
        frames += _episode_frames(run, agent_index, epsilon, max_steps, seed + episode, every)
    if not frames:
        raise ValueError("no frames were drawn")
    images = [Image.fromarray(np.asarray(f, dtype=np.uint8)) for f in frames]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(1000 / fps),
                   loop=0)  # fmt: skip
    return path


def _episode_frames(run: Run, p: int, epsilon: float, max_steps: int, seed: int,
                    every: int) -> list[np.ndarray]:  # fmt: skip
    """One episode of agent ``p`` alone, frozen, as RGB frames."""
    config = run.config
    single = frozen_agent(run, epsilon, seed, rows=[p])
    if config.env is None:
        from skillchain_torch.envs.pinball import PinballEnv
        from skillchain_torch.envs.pinball.render import render_frame

        env = PinballEnv(config.map, batch_size=[1], max_episode_steps=max_steps, seed=seed)
        td = env.reset()
        frames = [render_frame(env.pinball_map, td["state"][0])]
        action = single.begin(td["observation"].to(torch.float64))
        for t in range(max_steps):
            td = env.step(td.set("action", action))
            nxt = td["next"]
            if t % every == 0:
                frames.append(render_frame(env.pinball_map, nxt["state"][0]))
            if bool(nxt["terminated"].any() | nxt["truncated"].any()):
                break
            action = single.observe(nxt["observation"].to(torch.float64),
                                    nxt["reward"].reshape(1).to(torch.float64))  # fmt: skip
            td = env.step_mdp(td)
        return frames
    import os

    import gymnasium as gym

    from skillchain_torch.envs.external import make_env, read_specs

    os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # (pygame draws off-screen, no display)
    os.environ.setdefault("SDL_AUDIODRIVER", "dummy")

    sizes = read_specs(make_env(config.env), config.obs_bounds)
    env = gym.make(config.env.partition(":")[2], render_mode="rgb_array")
    if env.metadata.get("render_modes") and "rgb_array" not in env.metadata["render_modes"]:
        raise ValueError(f"{config.env} draws no rgb_array frames: it cannot be rendered")
    obs, _ = env.reset(seed=seed)
    scale = lambda o: sizes.scale(torch.as_tensor(np.asarray(o, dtype=np.float32)))[None]  # noqa: E731
    frames = [env.render()]
    action = single.begin(scale(obs))
    for t in range(max_steps):
        obs, reward, terminated, truncated, _ = env.step(int(action[0]))
        if t % every == 0:
            frames.append(env.render())
        if terminated or truncated:
            break
        action = single.observe(scale(obs), torch.tensor([float(reward)], dtype=torch.float64))
    env.close()
    return frames
