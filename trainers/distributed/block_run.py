"""One block of a sharded run, trained where a Ray worker (or a ``reproduce`` job) runs it.

:func:`run_block` trains agents ``[a, b)`` as an ordinary population run in the block's own
folder (:func:`~.blocks.block_config`), resuming from the block's newest checkpoint: a task
that Ray retries after its worker died continues from the dead worker's last checkpoint, bit
for bit (the checkpoint contract). It writes the block's arrays, and ``block.json`` last; a
finished block is not run again. Its counts go to the driver's progress actor as absolute
numbers, so a retried block is never counted twice.

Example:
    >>> import tempfile
    >>> config = TrainConfig(map="pinball_box", runs=2, episodes=1, max_episode_steps=20)
    >>> record = run_block(config, tempfile.mkdtemp())
    >>> record["agents"], 0 < record["agent_steps"] <= 40
    (2, True)
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.config.config import TrainConfig
from skillchain_torch.trainers.distributed.blocks import DONE

__all__ = ["run_block"]


class _Reporter:
    """Trainer hook sending a block's counts to the progress actor, at most once a second."""

    def __init__(self, actor, key: str, interval: float = 1.0):
        self.actor, self.key, self.interval = actor, key, interval
        self._last = -float("inf")

    def register(self, trainer) -> None:
        trainer.register_op("pre_train", self.send, name="ray_progress")
        trainer.register_op("post_episodes", lambda t, batch: self.send(t), name="ray_progress")
        trainer.register_op("post_train", lambda t: self.send(t, force=True), name="ray_progress")

    def send(self, trainer, force: bool = False) -> None:
        now = time.monotonic()
        if force or now - self._last >= self.interval:
            self._last = now
            self.actor.report.remote(self.key, int(trainer.episodes_done.sum()),
                                     int(trainer.agent_steps))


def run_block(config: TrainConfig, block_dir: str | Path, threads: int = 1,
              native: bool | None = None, progress=None, crash_once: str | None = None) -> dict:
    """Train one block in ``block_dir`` (resuming from its newest checkpoint) and write its
    arrays; returns its ``block.json`` record. A finished block is not run again.

    ``crash_once``: a test hook, a marker file; when it does not exist yet, the worker creates
    it and dies right after the block's first checkpoint (as a killed worker would).
    """
    from skillchain_torch.trainers.loop.population import PopulationTrainer
    from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint, resume_checkpoint

    block_dir = Path(block_dir)
    if (block_dir / DONE).is_file():
        saved = TrainConfig.load_json(block_dir / "config.json").mismatches(config)
        if saved:  # never merge another run's rows
            raise ValueError(f"{block_dir} holds a block of another run (fields "
                             f"{', '.join(saved)} differ); remove it")  # fmt: skip
        return json.loads((block_dir / DONE).read_text())
    trainer = PopulationTrainer(config, out_dir=block_dir, num_threads=threads, native=native)
    discovery = None
    if getattr(trainer.agent, "discovery", None) is not None:
        from skillchain_torch.trainers.outputs.discovery_log import DiscoveryLog

        discovery = DiscoveryLog()
        discovery.register(trainer)
    if latest_checkpoint(block_dir) is not None:
        resume_checkpoint(block_dir, trainer)
    else:
        block_dir.mkdir(parents=True, exist_ok=True)
        config.save_json(block_dir / "config.json")
    if progress is not None:
        _Reporter(progress, str(block_dir)).register(trainer)  # unique across a sweep's cells
    if crash_once is not None and not Path(crash_once).exists():
        def die(trainer, path):
            Path(crash_once).touch()
            os._exit(1)  # no cleanup, as a killed process

        trainer.register_op("post_checkpoint", die, name="crash_once")
    trainer.train()
    np.save(block_dir / "returns.npy", trainer.returns)
    np.save(block_dir / "lengths.npy", trainer.lengths)
    if discovery is not None:
        from skillchain_torch.trainers.outputs.discovery_log import option_tree

        trainer.agent.bank.save(block_dir / "options.pt")
        np.save(block_dir / "n_options.npy", discovery.n_options)
        np.save(block_dir / "option_outcomes.npy", discovery.outcomes)
        (block_dir / "option_tree.json").write_text(json.dumps(option_tree(trainer.agent)) + "\n")
    record = {"agents": config.runs, "seed": config.seed, "agent_steps": int(trainer.agent_steps),
              "wall_time_s": trainer.elapsed,
              "compiled_agent": bool(getattr(trainer.agent, "native", False))}
    tmp = block_dir / (DONE + ".tmp")
    tmp.write_text(json.dumps(record, indent=1) + "\n")
    os.replace(tmp, block_dir / DONE)  # the block counts as done only once all is written
    return record
