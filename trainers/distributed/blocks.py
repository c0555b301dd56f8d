"""How ``--workers`` cuts a run's P agents into blocks, and the record it keeps of the cut.

By the seed contract the agents ``[a, b)`` of a run seeded ``S`` are the population run with
``runs = b - a`` and ``seed = S + a``, bit for bit (:func:`block_config`). A sharded run
(:class:`ShardedRun`) trains each block in ``RUN_DIR/blocks/<a>-<b>/``
(:mod:`.block_run`), records its blocks and the driver's wall time in ``RUN_DIR/sharding.json``
(``SHARDING``, read by ``--resume``), and takes a block as finished once its ``block.json``
(``DONE``) is written. :func:`plan_blocks` chooses the blocks.

Example:
    >>> plan_blocks(10, 2), plan_blocks(10, 2, block_size=4)
    ([(0, 5), (5, 10)], [(0, 4), (4, 8), (8, 10)])
    >>> run = ShardedRun(TrainConfig(runs=10), Path("runs/flat"), plan_blocks(10, 2))
    >>> run.block_dir(run.spans[1]).as_posix()
    'runs/flat/blocks/5-10'
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from skillchain_torch.trainers.config.config import TrainConfig

__all__ = ["SHARDING", "DONE", "guided_spans", "plan_blocks", "block_spans", "block_config",
           "ShardedRun", "extend_blocks", "record_driver_wall", "previous_driver_wall"]

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


def extend_blocks(run: ShardedRun, native: bool | None = None) -> None:
    """Make every block of ``run`` (whose config asks for more episodes than its blocks ran)
    continue from its newest checkpoint before any of its agents finished, as ``--resume
    --episodes N`` does for a one-process run: the later checkpoints move into
    ``checkpoints/superseded/``, a finished block's ``block.json`` beside them (so the block
    runs again), and the block's ``config.json`` takes the new length. A block not yet started
    is left as it is.

    Every block is checked first (its checkpoint found and restored into a trainer of the new
    length, ``native`` as the run will be), and only then is any file moved: a block that
    cannot be extended raises ``ValueError`` in one line and leaves the run as it was."""
    from skillchain_torch.trainers.loop.population import PopulationTrainer
    from skillchain_torch.trainers.outputs.checkpoint import (
        _checkpoints,
        _restore,
        extension_checkpoint,
        supersede_after,
    )

    plan = []
    for span in run.spans:
        block_dir = run.block_dir(span)
        if not _checkpoints(block_dir):
            if (block_dir / DONE).is_file():
                raise ValueError(f"{block_dir}: a finished block without checkpoints cannot be "
                                 "extended; train the run again with more --episodes")
            continue
        config = block_config(run.config, *span, block_dir)
        path, state = extension_checkpoint(block_dir)
        try:  # (a trial: the block's own run restores it again when it starts)
            _restore(state, path, PopulationTrainer(config, native=native), extend=True)
        except ValueError as err:
            raise ValueError(f"{block_dir}: cannot be extended ({err})") from None
        plan.append((block_dir, path, config))
    for block_dir, path, config in plan:
        supersede_after(block_dir, path)
        if (block_dir / DONE).is_file():
            aside = block_dir / "checkpoints" / "superseded"
            aside.mkdir(exist_ok=True)
            (block_dir / DONE).replace(aside / DONE)
        config.save_json(block_dir / "config.json")


def record_driver_wall(out: Path, seconds: float) -> None:
    """Add ``seconds`` to the driver time saved in ``out/sharding.json`` (for --resume)."""
    path = Path(out) / SHARDING
    record = json.loads(path.read_text())
    record["driver_wall_time_s"] = record.get("driver_wall_time_s", 0.0) + seconds
    path.write_text(json.dumps(record) + "\n")


def previous_driver_wall(out: Path) -> float:
    """Driver seconds of earlier invocations of a resumed run (saved in sharding.json)."""
    try:
        return float(json.loads((out / SHARDING).read_text()).get("driver_wall_time_s", 0.0))
    except (OSError, ValueError):
        return 0.0
