"""One run's agents sharded across Ray workers: ``skillchain train ... --workers N``.

By the seed contract the agents ``[a, b)`` of a run seeded ``S`` are the population run with
``runs = b - a`` and ``seed = S + a``, bit for bit. So a run of P agents is cut into blocks,
each block trains as an ordinary population run in ``RUN_DIR/blocks/<a>-<b>/`` (its own
``config.json`` and checkpoints), and the driver then merges the blocks into exactly the files a
one-process run writes: ``returns.npy``, ``lengths.npy`` (rows in agent order), the TensorBoard
population scalars over all agents, ``learning_curve.png``, ``run_info.json``, and for skill
chaining ``options.pt``, ``n_options.npy``, ``option_tree.json`` and
``option_trajectory.png`` (its candidate agents replayed on the workers from the blocks' last
checkpoints, which stay in the blocks).

Why Ray core tasks, not Ray Tune: Tune runs trials of a search, each a configuration with its
own stopping rule; a block is a slice of one population run whose rows must be merged bit for
bit, which is exactly one remote function call. Load balancing is dynamic: one task per block
and at most ``workers`` in flight (``ray.wait``), so whichever worker frees up takes the next
block, and a run no longer waits on P/N agents that happen to be slow together.

Failures: a task whose worker dies is retried by Ray (``max_retries``), and a block always
resumes from its newest checkpoint, so the retry continues where the dead worker's last
checkpoint was (bit for bit, the checkpoint contract). A finished block writes ``block.json``
last; ``--resume RUN_DIR`` skips those and resumes the others. Nothing is counted twice: the
progress bar holds each block's absolute counts, not increments.

By default each worker takes one block (batched steps are worth more than balancing; see
:func:`plan_blocks`); ``--block-size`` cuts smaller blocks, handed out as workers free up.

Example (two workers on this machine, blocks of 2 agents):
    skillchain train --agent flat --runs 8 --episodes 100 --out runs/flat --workers 2 \\
        --block-size 2
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from pathlib import Path

import numpy as np

from .config import TrainConfig

__all__ = ["block_spans", "guided_spans", "plan_blocks", "block_config", "run_block", "require_ray",
           "ShardedRun", "run_sharded", "merge_blocks", "RAY_MISSING"]

RAY_MISSING = "needs Ray, which is not installed: pip install skillchain_torch[ray]"
SHARDING = "sharding.json"  # RUN_DIR's record of the blocks (read by --resume)
DONE = "block.json"  # written last by a finished block


def guided_spans(runs: int, workers: int) -> list[tuple[int, int]]:
    """Blocks that shrink as the run goes (guided self-scheduling): each takes a ``2 * workers``-th
    of the agents not yet handed out. The first blocks are large, so most agents share the
    batched steps (a flat agent's step costs ~10x less per agent at P = 100 than alone); the
    last are single agents, so the run's tail is spread over every worker.

    Example:
        >>> guided_spans(10, 2)
        [(0, 3), (3, 5), (5, 7), (7, 8), (8, 9), (9, 10)]
        >>> [b - a for a, b in guided_spans(100, 2)]
        [25, 19, 14, 11, 8, 6, 5, 3, 3, 2, 1, 1, 1, 1]
    """
    spans, a = [], 0
    while a < runs:
        size = max(1, -(-(runs - a) // (2 * workers)))
        spans.append((a, a + size))
        a += size
    return spans


def plan_blocks(runs: int, workers: int,
                block_size: int | str | None = None) -> list[tuple[int, int]]:  # fmt: skip
    """Blocks of ``block_size`` agents, by default one block per worker (``"shrink"``:
    :func:`guided_spans`).

    One block per worker is the default because batching is worth more than balancing here:
    measured on an idle 2-core machine (``benchmarks/README.md``), skill chaining 10 x 40 took
    0.43x one process's time in 2 blocks and 0.88x in :func:`guided_spans`'s 6 shrinking
    blocks, whose single-agent blocks pay a step ~10x dearer per agent than a batched one.
    Smaller blocks are handed out as workers free up (``--block-size``).

    Example:
        >>> plan_blocks(10, 2), plan_blocks(10, 2, block_size=3)
        ([(0, 5), (5, 10)], [(0, 3), (3, 6), (6, 9), (9, 10)])
    """
    if block_size == "shrink":
        return guided_spans(runs, workers)
    size = -(-runs // max(1, workers)) if block_size is None else block_size
    return block_spans(runs, size)


def block_spans(runs: int, block_size: int) -> list[tuple[int, int]]:
    """The agent ranges ``[a, b)`` of blocks of ``block_size`` agents (the last may be short).

    Example:
        >>> block_spans(5, 2)
        [(0, 2), (2, 4), (4, 5)]
    """
    return [(a, min(a + block_size, runs)) for a in range(0, runs, block_size)]


def block_config(config: TrainConfig, a: int, b: int, block_dir: Path) -> TrainConfig:
    """The population run of agents ``[a, b)`` of ``config`` (the seed contract: ``seed + a``).

    A given-options run with ``--options-agent each`` gives agent p saved agent p mod N's
    options; a block's agent q is agent a + q, so the block gets a file of exactly those.
    """
    block = dataclasses.replace(config, runs=b - a, seed=config.seed + a)
    if config.agent == "given-options" and config.options_agent is None:
        from skillchain_torch.options import OptionBank

        path = block_dir / "given_options.pt"
        if not path.is_file():
            saved = OptionBank.load(config.options)
            path.parent.mkdir(parents=True, exist_ok=True)
            saved.select_agents([p % saved.population for p in range(a, b)]).save(path)
        block = dataclasses.replace(block, options=str(path))
    return block


def require_ray(what: str = "--workers"):
    """The ``ray`` module, or ``ImportError`` with one line naming ``what`` and the extra."""
    try:
        import ray
    except ImportError:
        raise ImportError(f"{what} {RAY_MISSING}") from None
    return ray


class _Progress:
    """Per-block ``(episodes, agent steps)``, absolute so a retried block is never counted
    twice; a Ray actor that the blocks report to and the driver reads."""

    def __init__(self):
        self.blocks: dict[str, tuple[int, int]] = {}

    def report(self, key: str, episodes: int, steps: int) -> None:
        self.blocks[key] = (episodes, steps)

    def totals(self) -> tuple[int, int]:
        return (sum(e for e, _ in self.blocks.values()), sum(s for _, s in self.blocks.values()))


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
    from .checkpoint import latest_checkpoint, resume_checkpoint
    from .population import PopulationTrainer

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
        from .discovery_log import DiscoveryLog

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
        from .discovery_log import option_tree

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


@dataclasses.dataclass
class ShardedRun:
    """A run to shard: its config, its directory and its blocks (``[a, b)`` agent ranges)."""

    config: TrainConfig
    out: Path
    spans: list[tuple[int, int]]

    def block_dir(self, span: tuple[int, int]) -> Path:
        return self.out / "blocks" / f"{span[0]}-{span[1]}"

    def save(self, workers: int) -> None:
        record = {"workers": workers, "blocks": [list(s) for s in self.spans]}
        (self.out / SHARDING).write_text(json.dumps(record) + "\n")

    @classmethod
    def load(cls, out: Path, config: TrainConfig) -> ShardedRun:
        record = json.loads((Path(out) / SHARDING).read_text())
        return cls(config, Path(out), [tuple(s) for s in record["blocks"]])


def block_trajectory(config: TrainConfig, block_dir: str | Path, agent: int,
                     offset: int) -> dict:
    """The Figure 4b candidates of agent ``agent`` of a finished block (its greedy and
    epsilon-greedy episodes, :func:`~.option_trajectory.best_greedy_trajectory`), rebuilt from
    the block's last checkpoint; ``agent`` in the result is the run's index (+ ``offset``)."""
    from .checkpoint import resume_checkpoint
    from .option_trajectory import best_greedy_trajectory
    from .population import PopulationTrainer

    trainer = PopulationTrainer(config, out_dir=block_dir)
    resume_checkpoint(block_dir, trainer)
    run = best_greedy_trajectory(trainer.agent, config.map, agents=[agent])
    return {**run, "agent": offset + agent}


def _init_ray(ray, workers: int, address: str | None) -> None:
    """A local Ray of ``workers`` CPUs, or the cluster at ``address`` (``RAY_ADDRESS`` too, as
    Ray reads it); reuses a Ray already started in this process (the tests' fixture)."""
    if ray.is_initialized():
        return
    kwargs = {"log_to_driver": False, "include_dashboard": False,  # one bar, no worker logs
              "configure_logging": False}
    if address is not None or os.environ.get("RAY_ADDRESS"):
        ray.init(address=address, **kwargs)
    else:
        # Ray starts its workers at nice 15: on a machine busy with other runs they would
        # wait behind them, where a one-process run (nice 0) does not.
        os.environ.setdefault("RAY_worker_niceness", "0")
        ray.init(num_cpus=workers, **kwargs)


def run_sharded(runs: list[ShardedRun], workers: int, address: str | None = None,
                threads: int = 1, native: bool | None = None, quiet: bool = False,
                crash_once: str | None = None) -> list[dict]:
    """Train the blocks of ``runs`` on Ray, ``workers`` at a time, and merge each run once its
    blocks are done; returns each run's ``run_info``.

    Blocks of every run share the one pool, so a sweep's cells fill the workers together. A
    run's merge is a Ray task too (writing TensorBoard's scalars of 100 x 250 episodes takes
    a while), so the driver keeps handing out blocks meanwhile. A block that fails (a
    diverged learner) raises ``RuntimeError`` naming it.
    """
    from tqdm.auto import tqdm

    ray = require_ray()
    _init_ray(ray, workers, address)
    task = ray.remote(num_cpus=1, max_retries=3)(run_block)
    # No CPU of its own: it mostly writes files, and its replays are tasks that take one.
    merge = ray.remote(num_cpus=0, max_retries=3)(merge_blocks)
    progress = ray.remote(num_cpus=0)(_Progress).remote()
    clock = time.perf_counter()
    todo = [(i, span) for i, run in enumerate(runs) for span in run.spans]
    left = {i: len(run.spans) for i, run in enumerate(runs)}
    records: dict[int, dict] = {i: {} for i in range(len(runs))}
    total = sum(r.config.runs * r.config.episodes for r in runs)
    agents = sum(r.config.runs for r in runs)
    bar = tqdm(total=total, unit="ep", desc=f"{len(todo)} blocks on {workers} workers",
               dynamic_ncols=True, disable=quiet)
    agents_done = finished = 0
    shown = (0, 0)
    in_flight: dict = {}  # block tasks: (run, span)
    merging: dict = {}  # merge tasks: run
    infos = [None] * len(runs)
    try:
        while todo or in_flight or merging:
            while todo and len(in_flight) < workers:
                i, span = todo.pop(0)
                run = runs[i]
                block_dir = run.block_dir(span)
                cfg = block_config(run.config, *span, block_dir)
                ref = task.remote(cfg, str(block_dir), threads, native, progress, crash_once)
                in_flight[ref] = (i, span)
            done, _ = ray.wait([*in_flight, *merging], num_returns=1, timeout=1.0)
            for ref in done:
                if ref in merging:
                    i = merging.pop(ref)
                    infos[i] = _result(ray, ref, [*in_flight, *merging], f"{runs[i].out}: merge")
                    continue
                i, span = in_flight.pop(ref)
                records[i][span] = _result(ray, ref, [*in_flight, *merging],
                                           f"{runs[i].out}: block {span[0]}-{span[1]}")
                agents_done += span[1] - span[0]
                finished += (span[1] - span[0]) * runs[i].config.episodes
                left[i] -= 1
                if left[i] == 0:
                    wall = time.perf_counter() - clock
                    merging[merge.remote(runs[i], records[i], workers, wall)] = i
            episodes, steps = ray.get(progress.totals.remote())
            episodes = max(episodes, finished)  # a block's last report may still be on its way
            if (episodes, agents_done) != shown:  # redraw on news only (a log file stays short)
                shown = (episodes, agents_done)
                bar.n = episodes
                elapsed = time.perf_counter() - clock
                bar.set_postfix(agents=f"{agents_done}/{agents}",
                                steps_s=f"{steps / elapsed if elapsed else 0:,.0f}", refresh=False)
                bar.refresh()
    finally:
        bar.close()
    return infos


def _result(ray, ref, others, what: str):
    """``ray.get(ref)``; if the task failed, cancel ``others`` and raise ``RuntimeError``
    naming ``what`` and the task's own error, on one line."""
    try:
        return ray.get(ref)
    except Exception as err:  # a diverged or broken block: stop the run
        for other in others:
            ray.cancel(other, force=True)
        reason = " ".join(str(getattr(err, "cause", None) or err).split())[:400]
        raise RuntimeError(f"{what} failed ({reason})") from None


def merge_blocks(run: ShardedRun, records: dict, workers: int, wall: float) -> dict:
    """Write ``run.out``'s one-process outputs from its finished blocks; returns run_info."""
    import platform

    import torch

    from .plots import save_learning_curve
    from .run_outputs import source_commit

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
                        title=f"{cfg.agent} on {cfg.map} ({cfg.runs} runs)")
    steps = sum(r["agent_steps"] for r in records.values())
    previous = _previous_wall(out)
    info = {
        "wall_time_s": previous + wall,
        "agent_steps": steps,
        "agent_steps_per_second": steps / (previous + wall) if previous + wall > 0 else 0.0,
        "block_wall_time_s": sum(r["wall_time_s"] for r in records.values()),
        "workers": workers,
        "block_size": max(b - a for a, b in run.spans),
        "blocks": len(run.spans),
        "torch": torch.__version__,
        "threads": 1,
        "compiled_agent": all(r.get("compiled_agent", False) for r in records.values()),
        "machine": platform.processor() or platform.machine(),
        "commit": source_commit(),
    }
    (out / "run_info.json").write_text(json.dumps(info, indent=2) + "\n")
    np.save(out / "returns.npy", returns)  # last: a sweep takes returns.npy as "complete"
    return info


def _previous_wall(out: Path) -> float:
    """Driver seconds of earlier invocations of a resumed run (saved in sharding.json)."""
    try:
        return float(json.loads((out / SHARDING).read_text()).get("driver_wall_time_s", 0.0))
    except (OSError, ValueError):
        return 0.0


def record_driver_wall(out: Path, seconds: float) -> None:
    """Add ``seconds`` to the driver time saved in ``out/sharding.json`` (for --resume)."""
    path = Path(out) / SHARDING
    record = json.loads(path.read_text())
    record["driver_wall_time_s"] = record.get("driver_wall_time_s", 0.0) + seconds
    path.write_text(json.dumps(record) + "\n")


def _merge_options(run: ShardedRun, dirs: list[Path]) -> np.ndarray:
    """``options.pt`` (one bank, agents in order), ``n_options.npy`` and ``option_tree.json``."""
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
    candidates replayed on a worker from its block's last checkpoint."""
    from skillchain_torch.options import OptionBank

    from .option_trajectory import save_option_trajectory, solution_rank

    held = OptionBank.load(run.out / "options.pt").live().sum(-1).numpy()
    last = np.nan_to_num(returns[:, -1], nan=-np.inf)
    order = sorted(range(len(held)), key=lambda p: (-held[p], -last[p]))[:8]
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


def _write_tensorboard(cfg: TrainConfig, out: Path, returns, lengths, n_options) -> None:
    """The population scalars of a one-process run, from the merged arrays."""
    import shutil

    from torchrl.record.loggers import TensorboardLogger

    from .logging import experiment_name, log_population_arrays

    shutil.rmtree(out / "tb", ignore_errors=True)  # a merge redone on --resume: no duplicates
    logger = TensorboardLogger(experiment_name(cfg), log_dir=str(out / "tb"))
    try:
        log_population_arrays(logger, cfg, returns, lengths, n_options)
    finally:
        logger.experiment.close()
