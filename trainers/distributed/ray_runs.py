"""One run's agents sharded across Ray workers: ``skillchain train ... --workers N``.

By the seed contract the agents ``[a, b)`` of a run seeded ``S`` are the population run with
``runs = b - a`` and ``seed = S + a``, bit for bit. So a run of P agents is cut into blocks
(:mod:`.blocks`), each block trains as an ordinary population run in ``RUN_DIR/blocks/<a>-<b>/``
(:mod:`.block_run`: its own ``config.json`` and checkpoints), and the blocks are then merged into
exactly the files a one-process run writes (:mod:`.block_merge`). This module is the driver,
:func:`run_sharded`: it hands the blocks to Ray and the merges too.

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
:func:`~.blocks.plan_blocks`); ``--block-size`` cuts smaller blocks, handed out as workers free
up.

Example (two workers on this machine, blocks of 2 agents):
    skillchain train --agent flat --runs 8 --episodes 100 --out runs/flat --workers 2 \\
        --block-size 2
"""

from __future__ import annotations

import os
import time

from skillchain_torch.trainers.distributed.block_merge import merge_blocks
from skillchain_torch.trainers.distributed.block_run import run_block
from skillchain_torch.trainers.distributed.blocks import ShardedRun, block_config
from skillchain_torch.trainers.outputs.run_outputs import source_commit

__all__ = ["require_ray", "run_sharded", "RAY_MISSING"]

RAY_MISSING = "needs Ray, which is not installed: pip install skillchain_torch[ray]"


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
    commit = source_commit()  # the driver's, read as the command started (cli.py)
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
                    merging[merge.remote(runs[i], records[i], workers, wall, commit)] = i
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
