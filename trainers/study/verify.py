"""``skillchain verify RUN_DIR --agents 3 7``: re-run published agents alone, compare bit for bit.

By the seed contract agent ``p`` of a population started with seed ``S`` is the single agent
with seed ``S + p``, whatever the other agents did. So any agent of a published run can be
re-run on its own from the directory's ``config.json`` in a fraction of the run's time, and
its returns and lengths must equal row ``p`` of ``returns.npy`` and ``lengths.npy`` exactly.
Runs with an MLP top level or MLP option heads are refused: their replay buffers are shared by
the population, so only the whole command reproduces them.

A given-options run whose agents took saved agent ``p mod N``'s options (``--options-agent
each``) re-runs agent ``p`` with saved agent ``p mod N``'s, from its options file
(``config.options``, read as given or relative to the run directory's parent folders). Option
banks are often too big to publish: when the file is absent but the folder it was written to
holds the skill-chaining run's ``config.json`` and arrays, that agent's options are rebuilt by
re-running the skill-chaining agent alone (the seed contract again), which verifies it too.

Example:
    >>> import tempfile, numpy as np
    >>> from skillchain_torch.trainers import PopulationTrainer, TrainConfig
    >>> out = tempfile.mkdtemp()
    >>> cfg = TrainConfig(runs=3, episodes=2, max_episode_steps=30, seed=5)
    >>> trainer = PopulationTrainer(cfg); _ = trainer.train(); trainer.write_results(out)
    >>> cfg.save_json(f"{out}/config.json")
    >>> [r["match"] for r in verify_run(out, [0, 2])]
    [True, True]
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from skillchain_torch.trainers.config.config import TrainConfig

__all__ = ["verify_run", "resolve_options_path"]


def _beside(options: str, run_dir: Path):
    """``options`` relative to ``run_dir`` and to each folder above it, nearest first (a
    study's given-options runs name their options relative to the study's folder)."""
    for base in (run_dir, *run_dir.resolve().parents):
        yield base / options


def resolve_options_path(options: str, run_dir: Path) -> Path:
    """``options`` as given if it exists, else relative to ``run_dir`` or a folder above it."""
    path = Path(options)
    if path.is_file() or path.is_absolute():
        return path
    return next((c for c in _beside(options, run_dir) if c.is_file()), path)


def _saved_population(path: Path) -> int:
    from skillchain_torch.options import OptionBank

    return OptionBank.load(path).population


def _source_run(options: str, run_dir: Path) -> Path | None:
    """The skill-chaining run directory that wrote ``options`` (``DIR/options.pt``), if present."""
    for candidate in _beside(options, run_dir):
        source = candidate.parent
        if all((source / n).is_file() for n in ("config.json", "returns.npy", "lengths.npy")):
            return source
    return None


def verify_run(run_dir: str | Path, agents, native: bool | None = None,
               progress: bool = False, keep_options: Path | None = None) -> list[dict]:  # fmt: skip
    """Re-run ``agents`` of the run in ``run_dir`` one at a time; one dict per agent with
    ``agent``, ``seed``, ``match``, ``returns_match``, ``lengths_match``, ``first_difference``
    (the first episode that differs, or ``None``) and ``wall_time_s``.

    ``native``: the kernels to re-run with (default: those ``run_info.json`` names, else the
    default). ``keep_options``: where to save the options of an agent that matched (how a
    given-options run's options are rebuilt). ``ValueError`` names a missing file or an agent
    outside the run.
    """
    from skillchain_torch.trainers.loop.population import PopulationTrainer

    run_dir = Path(run_dir)
    for name in ("config.json", "returns.npy", "lengths.npy"):
        if not (run_dir / name).is_file():
            raise ValueError(f"{run_dir}: no {name} (not a finished run directory)")
    config = TrainConfig.load_json(run_dir / "config.json").resolved()
    replayed = [f"--{f.replace('_', '-')} mlp" for f in ("top_head", "option_head")
                if getattr(config, f) == "mlp"]  # fmt: skip
    if replayed:  # batched matmuls may round by population size: one agent alone drifts
        raise ValueError(f"{run_dir}: a run with {' and '.join(replayed)} cannot be re-run agent "
                         f"by agent bit for bit (each agent has its own replay memory, but its "
                         f"networks' batched matmuls may round the last bits differently in a "
                         f"population of one; results/neural/README.md); re-run the whole "
                         f"command to reproduce it")  # fmt: skip
    returns, lengths = np.load(run_dir / "returns.npy"), np.load(run_dir / "lengths.npy")
    if returns.shape != (config.runs, config.episodes) or lengths.shape != returns.shape:
        raise ValueError(f"{run_dir}: returns.npy {returns.shape} / lengths.npy {lengths.shape} "
                         f"do not match config.json's runs x episodes "
                         f"({config.runs}, {config.episodes})")  # fmt: skip
    if native is None and (run_dir / "run_info.json").is_file():
        info = json.loads((run_dir / "run_info.json").read_text())
        native = False if info.get("compiled_agent") is False else None
    changes = {}
    saved = source = None
    if config.agent == "given-options":
        path = resolve_options_path(config.options, run_dir)
        if path.is_file():
            changes["options"] = str(path)
            if config.options_agent is None:
                saved = _saved_population(path)
        elif (source := _source_run(config.options, run_dir)) is None:
            raise ValueError(f"{run_dir}: its options file {config.options!r} is not here, nor "
                             f"the skill-chaining run that wrote it (given-options runs need "
                             f"one of them to be re-run)")  # fmt: skip
    for p in agents:
        if not 0 <= int(p) < config.runs:
            raise ValueError(f"agent {p} is not in {run_dir} (agents 0..{config.runs - 1})")
    results = []
    for p in agents:
        p = int(p)
        single = dataclasses.replace(config, runs=1, seed=config.seed + p, checkpoint_every=0,
                                     **changes)  # fmt: skip
        if saved is not None:
            single = dataclasses.replace(single, options_agent=p % saved)
        if source is not None:
            single = _rebuilt_options(single, source, p, config.options_agent, native, progress)
        trainer = PopulationTrainer(single, native=native)
        trainer.train()
        same_r = np.array_equal(trainer.returns[0], returns[p], equal_nan=True)
        same_l = np.array_equal(trainer.lengths[0], lengths[p])
        differ = np.nonzero((trainer.returns[0] != returns[p]) | (trainer.lengths[0] != lengths[p]))
        first = int(differ[0][0]) + 1 if differ[0].size else None
        if keep_options is not None and same_r and same_l:  # only verified options rebuild
            keep_options.parent.mkdir(parents=True, exist_ok=True)  # a given-options run
            trainer.agent.bank.save(keep_options)
        results.append({"agent": p, "seed": single.seed, "match": same_r and same_l,
                        "returns_match": same_r, "lengths_match": same_l,
                        "first_difference": first, "wall_time_s": trainer.elapsed,
                        "agent_steps": int(trainer.agent_steps)})  # fmt: skip
        if progress:
            r = results[-1]
            print(f"agent {p} (seed {single.seed}): {'match' if r['match'] else 'MISMATCH'}"
                  + ("" if first is None else f" from episode {first}")
                  + f" ({r['agent_steps']:,} steps, {r['wall_time_s']:.1f} s)", flush=True)
    return results


def _rebuilt_options(single: TrainConfig, source: Path, p: int, options_agent, native,
                     progress: bool) -> TrainConfig:  # fmt: skip
    """``single`` with its options rebuilt: the source run's agent (``options_agent``, or ``p``
    mod its runs) re-run alone and verified, its bank saved beside the source run (a
    ``verify-options/`` cache, reused by the next verify)."""
    runs = TrainConfig.load_json(source / "config.json").runs
    q = options_agent if options_agent is not None else p % runs
    cache = source / "verify-options" / f"agent{q}.pt"
    if not cache.is_file():
        [check] = verify_run(source, [q], native=native, progress=progress, keep_options=cache)
        if not check["match"]:
            episode = check["first_difference"]
            raise ValueError(f"{source}: agent {q} does not reproduce (episode {episode}), "
                             f"so its options cannot be rebuilt")  # fmt: skip
    elif progress:
        print(f"options of {source} agent {q}: {cache}", flush=True)
    return dataclasses.replace(single, options=str(cache), options_agent=0)
