"""A sharded run's finished blocks merged into exactly the files a one-process run writes.

:func:`merge_blocks` writes ``returns.npy`` and ``lengths.npy`` (rows in agent order), the
TensorBoard population scalars over all agents, ``learning_curve.png`` and ``run_info.json``,
and for skill chaining ``options.pt``, ``n_options.npy``, ``option_tree.json`` and
``option_trajectory.png``: its candidate agents are replayed from their blocks' last checkpoints
(:func:`block_trajectory`), which stay in the blocks, on the Ray workers when Ray is running.

Example:
    >>> import tempfile
    >>> from skillchain_torch.trainers.distributed.block_run import run_block
    >>> config = TrainConfig(map="pinball_box", runs=3, episodes=1, max_episode_steps=20)
    >>> run = ShardedRun(config, Path(tempfile.mkdtemp()), [(0, 2), (2, 3)])
    >>> records = {span: run_block(block_config(config, *span, run.block_dir(span)),
    ...                            run.block_dir(span)) for span in run.spans}
    >>> info = merge_blocks(run, records, workers=2, wall=1.0, commit="0123abc")
    >>> np.load(run.out / "returns.npy").shape, info["blocks"], info["block_size"]
    ((3, 1), 2, 2)
    >>> json.loads((run.out / "run_info.json").read_text())["commit"]  # the driver's, not ours
    '0123abc'
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.config.config import TrainConfig
from skillchain_torch.trainers.distributed.blocks import (
    ShardedRun,
    block_config,
    previous_driver_wall,
)

__all__ = ["merge_blocks", "block_trajectory", "run_wall_time"]


def run_wall_time(driver: float, records: dict) -> float:
    """A sharded run's wall time: the drivers' recorded time, but never less than its longest
    block's. A driver records its time only when it stops cleanly or on Ctrl-C, so a run resumed
    after its driver was killed (a session's end) would otherwise report only the last driver's
    share, while each block's time survives in its checkpoints.

    Example:
        >>> run_wall_time(1716.0, {(0, 50): {"wall_time_s": 10513.0},
        ...                        (50, 100): {"wall_time_s": 9800.0}})
        10513.0
        >>> run_wall_time(4000.0, {(0, 50): {"wall_time_s": 3600.0}})
        4000.0
    """
    longest = max((float(r["wall_time_s"]) for r in records.values()), default=0.0)
    return max(float(driver), longest)


def merge_blocks(run: ShardedRun, records: dict, workers: int, wall: float,
                 commit: str | None = None) -> dict:  # fmt: skip
    """Write ``run.out``'s one-process outputs from its finished blocks; returns run_info.

    ``commit``: the code the run ran, as the driver read it when it started (the merge is a
    Ray task in another process, where :func:`.run_outputs.source_commit` would read the
    checkout as it is at the end of the run); ``None``: read it here."""
    import platform

    import torch

    from skillchain_torch.trainers.outputs.plots import save_learning_curve
    from skillchain_torch.trainers.outputs.run_outputs import source_commit

    cfg, out = run.config, run.out
    dirs = [run.block_dir(s) for s in run.spans]
    returns = np.concatenate([np.load(d / "returns.npy") for d in dirs])
    lengths = np.concatenate([np.load(d / "lengths.npy") for d in dirs])
    np.save(out / "lengths.npy", lengths)
    cfg.save_json(out / "config.json")
    n_options = None
    if (dirs[0] / "options.pt").is_file():
        n_options = _merge_options(run, dirs)
        _option_trajectory(run, returns)
    _write_tensorboard(cfg, out, returns, lengths, n_options)
    save_learning_curve(returns, out / "learning_curve.png",
                        title=f"{cfg.agent} on {cfg.env_name} ({cfg.runs} runs)")
    steps = sum(r["agent_steps"] for r in records.values())
    total = run_wall_time(previous_driver_wall(out) + wall, records)
    info = {
        "wall_time_s": total,
        "agent_steps": steps,
        "agent_steps_per_second": steps / total if total > 0 else 0.0,
        "block_wall_time_s": sum(r["wall_time_s"] for r in records.values()),
        "workers": workers,
        "block_size": max(b - a for a, b in run.spans),
        "blocks": len(run.spans),
        "torch": torch.__version__,
        "threads": 1,
        "compiled_agent": all(r.get("compiled_agent", False) for r in records.values()),
        "machine": platform.processor() or platform.machine(),
        "commit": source_commit() if commit is None else commit,
    }
    (out / "run_info.json").write_text(json.dumps(info, indent=2) + "\n")
    np.save(out / "returns.npy", returns)  # last: a sweep takes returns.npy as "complete"
    return info


def _merge_options(run: ShardedRun, dirs: list[Path]) -> np.ndarray:
    """``options.pt`` (one bank, agents in order), ``n_options.npy``, ``option_outcomes.npy``
    and ``option_tree.json``."""
    from skillchain_torch.options import OptionBank

    OptionBank.concat([OptionBank.load(d / "options.pt") for d in dirs]).save(
        run.out / "options.pt")
    n_options = np.concatenate([np.load(d / "n_options.npy") for d in dirs])
    np.save(run.out / "n_options.npy", n_options)
    if all((d / "option_outcomes.npy").exists() for d in dirs):  # (blocks of older runs lack it)
        np.save(run.out / "option_outcomes.npy",
                np.concatenate([np.load(d / "option_outcomes.npy") for d in dirs]))
    trees = [json.loads((d / "option_tree.json").read_text()) for d in dirs]
    agents = [{**agent, "agent": a + agent["agent"]}
              for (a, _), tree in zip(run.spans, trees) for agent in tree["agents"]]
    tree = {**trees[0], "agents": agents}
    (run.out / "option_tree.json").write_text(json.dumps(tree, indent=1) + "\n")
    return n_options


def _option_trajectory(run: ShardedRun, returns: np.ndarray) -> None:
    """``option_trajectory.png`` as a one-process run draws it: the best greedy solution among
    the eight agents holding the most options (ties: the best last return), each agent's
    candidates replayed on a worker from its block's last checkpoint; off Pinball, the two
    that hold the most, read from their checkpoints (:func:`block_env_trajectory`)."""
    from skillchain_torch.options import OptionBank
    from skillchain_torch.trainers.outputs.option_trajectory import (
        figure_candidates,
        save_option_trajectory,
        solution_rank,
    )

    held = OptionBank.load(run.out / "options.pt").live().sum(-1).numpy()
    if run.config.env is not None:  # off Pinball, as the one-process run
        from skillchain_torch.trainers.outputs.env_trajectory import save_env_trajectory

        candidates = [block_env_trajectory(run, p) for p in figure_candidates(held)]
        save_env_trajectory(max(candidates, key=solution_rank),
                            run.out / "option_trajectory.png")  # fmt: skip
        return
    order = figure_candidates(held, returns[:, -1])
    calls = []
    for p in order:  # the one-process order, so ties go to the same agent
        a, b = next(span for span in run.spans if span[0] <= p < span[1])
        cfg = block_config(run.config, a, b, run.block_dir((a, b)))
        calls.append((cfg, str(run.block_dir((a, b))), p - a, a))
    try:
        import ray
    except ImportError:
        ray = None
    if ray is not None and ray.is_initialized():  # replayed on the workers
        task = ray.remote(num_cpus=1)(block_trajectory)
        candidates = ray.get([task.remote(*call) for call in calls])
    else:  # a merge in its own process (skillchain reproduce): one after the other
        candidates = [block_trajectory(*call) for call in calls]
    best = max(candidates, key=solution_rank)
    save_option_trajectory(best, run.config.map, run.out / "option_trajectory.png")


def block_trajectory(config: TrainConfig, block_dir: str | Path, agent: int,
                     offset: int) -> dict:
    """The Figure 4b candidates of agent ``agent`` of a finished block (its greedy and
    epsilon-greedy episodes, :func:`~.option_trajectory.best_greedy_trajectory`), rebuilt from
    the block's last checkpoint; ``agent`` in the result is the run's index (+ ``offset``)."""
    from skillchain_torch.trainers.loop.population import PopulationTrainer
    from skillchain_torch.trainers.outputs.checkpoint import resume_checkpoint
    from skillchain_torch.trainers.outputs.option_trajectory import best_greedy_trajectory

    trainer = PopulationTrainer(config, out_dir=block_dir)
    resume_checkpoint(block_dir, trainer)
    run = best_greedy_trajectory(trainer.agent, config.map, agents=[agent])
    return {**run, "agent": offset + agent}


def block_env_trajectory(run: ShardedRun, p: int) -> dict:
    """Agent ``p``'s greedy episode in a fresh copy of the run's env (Figure 4b off Pinball),
    from the agent state of its block's last checkpoint: a Gymnasium env's simulator state is
    not saved, so the block cannot be resumed, but its agents can be read."""
    from skillchain_torch.trainers.loop.population import PopulationTrainer
    from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint, read_checkpoint
    from skillchain_torch.trainers.outputs.env_trajectory import best_env_trajectory

    a, b = next(span for span in run.spans if span[0] <= p < span[1])
    block_dir = run.block_dir((a, b))
    trainer = PopulationTrainer(block_config(run.config, a, b, block_dir))
    trainer.agent.load_state_dict(read_checkpoint(latest_checkpoint(block_dir))["agent"])
    found = best_env_trajectory(trainer.agent, run.config.env, agents=[p - a], tries=1,
                                obs_bounds=run.config.obs_bounds)  # fmt: skip
    return {**found, "agent": p}


def _write_tensorboard(cfg: TrainConfig, out: Path, returns, lengths, n_options) -> None:
    """The population scalars of a one-process run, from the merged arrays."""
    import shutil

    from torchrl.record.loggers import TensorboardLogger

    from skillchain_torch.trainers.outputs.logging import experiment_name, log_population_arrays

    shutil.rmtree(out / "tb", ignore_errors=True)  # a merge redone on --resume: no duplicates
    logger = TensorboardLogger(experiment_name(cfg), log_dir=str(out / "tb"))
    try:
        log_population_arrays(logger, cfg, returns, lengths, n_options)
    finally:
        logger.experiment.close()
