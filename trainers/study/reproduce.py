"""``skillchain reproduce paper --out DIR``: the paper's experiments, figures and report.

Six runs, each a normal run directory (``config.json``, ``returns.npy``, ``lengths.npy``, and
for skill chaining ``n_options.npy`` and ``option_tree.json``), under ``DIR/<instance>/<agent>``:

=========================  ===================================================================
``simple/flat``            Figure 4a's flat agents on ``pinball_simple_single`` (order 4)
``simple/skill-chaining``  Figure 4a's skill-chaining agents (the default reading)
``simple/given-options``   agents given options: agent p takes skill-chaining agent p's
                           options after its episodes (the paper: 250)
``hard/...``               the same three on ``pinball_hard_two_starts`` (order 5), Figure 6
=========================  ===================================================================

Every agent of an instance uses the same seeds (``--seed``, agent p: seed + p), so the agents
of different kinds are paired. By the seed contract agents ``[a, b)`` of a run are the
population run of ``b - a`` agents seeded ``seed + a``, bit for bit, so each run is cut into
``--jobs`` blocks (the layout of ``skillchain train --workers``: ``RUN_DIR/blocks/<a>-<b>/``),
and blocks, not runs, are the jobs: ``--jobs`` processes at a time (both cores of a 2-core
machine by default), the skill-chaining blocks first, as the given-options runs wait for their
options. A run's blocks are merged (in a process of their own) into the files a one-process run
writes. Whole runs as jobs left a core idle while one long skill-chaining run went on.
``DIR/timing.json`` records each invocation's wall time.
Then :mod:`.paper_report` writes ``DIR/README.md`` (tables with 95% intervals, the paper's
claims checked) and the figures (4a-8, :mod:`.paper_figures`).

Resumable: a finished run (``run_info.json``) is kept, an interrupted block continues from its
last checkpoint, a finished block (``block.json``) is kept; a run directory whose config differs
from the one asked for is refused by name. An interrupted run of an older, one-process study
(a checkpoint in the run directory itself) is finished in one process. Each run's log is
``DIR/<instance>/<agent>.log``.

Example (a tiny version; the full one is ``--runs 100 --episodes 250``):

    skillchain reproduce paper --out runs/paper_small --runs 4 --episodes 20 --hard-runs 2

From Python:
    >>> exps = paper_experiments(runs=4, episodes=20, hard_runs=2, hard_episodes=10, seed=7)
    >>> [e.name for e in exps][:3], exps[2].depends
    (['simple/flat', 'simple/skill-chaining', 'simple/given-options'], 'simple/skill-chaining')
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from skillchain_torch.trainers.config.config import TrainConfig

__all__ = ["Experiment", "paper_experiments", "run_state", "run_experiments", "train_dir",
           "experiment_spans", "INSTANCES"]  # fmt: skip

# The paper's two instances: map and the agents' shared settings.
INSTANCES = {"simple": "pinball_simple_single", "hard": "pinball_hard_two_starts"}
AGENT_ORDER = ("flat", "skill-chaining", "given-options")


@dataclass(frozen=True)
class Experiment:
    """One run of the study: ``name`` (``"<instance>/<agent>"``), its config, and the
    skill-chaining run whose options it is given (``depends``), if any."""

    name: str
    config: TrainConfig
    depends: str | None = None

    @property
    def instance(self) -> str:
        return self.name.split("/")[0]

    @property
    def agent(self) -> str:
        return self.name.split("/")[1]


def paper_experiments(runs: int = 100, episodes: int = 250, hard_runs: int | None = None,
                      hard_episodes: int | None = None, seed: int = 1000,
                      instances=("simple", "hard"), **reading) -> list[Experiment]:  # fmt: skip
    """The paper's runs: flat, skill chaining and given options on each instance.

    ``reading``: :class:`TrainConfig` reading fields (``gestation_positives``, ...) to use
    instead of the defaults. Given-options agents read ``<instance>/skill-chaining/options.pt``
    relative to the output directory (agent p takes saved agent p's options).
    """
    exps = []
    for instance in instances:
        if instance not in INSTANCES:
            raise ValueError(f"unknown instance {instance!r}; known: {', '.join(INSTANCES)}")
        n = runs if instance == "simple" or hard_runs is None else hard_runs
        e = episodes if instance == "simple" or hard_episodes is None else hard_episodes
        base = TrainConfig(map=INSTANCES[instance], runs=n, episodes=e, seed=seed, **reading)
        sc = f"{instance}/skill-chaining"
        for agent in AGENT_ORDER:
            cfg = dataclasses.replace(base, agent=agent)
            depends = None
            if agent == "given-options":
                cfg = dataclasses.replace(cfg, options=f"{sc}/options.pt", options_agent=None)
                depends = sc
            exps.append(Experiment(f"{instance}/{agent}", cfg.resolved(), depends))
    return exps


def run_state(run_dir: Path) -> str:
    """``"done"`` (``run_info.json`` written), ``"partial"`` (a checkpoint to resume from) or
    ``"new"``."""
    from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint

    if (run_dir / "run_info.json").is_file() and (run_dir / "returns.npy").is_file():
        return "done"
    if (run_dir / "config.json").is_file() and latest_checkpoint(run_dir) is not None:
        return "partial"
    return "new"


def _check_config(exp: Experiment, run_dir: Path) -> None:
    path = run_dir / "config.json"
    if not path.is_file():
        return
    saved = TrainConfig.load_json(path)
    differ = saved.mismatches(exp.config)
    if differ:
        raise ValueError(f"{path}: this run was made with other settings ({', '.join(differ)} "
                         f"differ from what was asked); use another --out or remove it")


def train_dir(run_dir: str | Path, quiet: bool = True, threads: int = 1) -> int:
    """Train the run described by ``run_dir/config.json``: continue it from its last checkpoint
    if it has one, else start it; nothing if it is done. The exit code of ``skillchain train``.
    """
    from skillchain_torch.trainers.loop.population import PopulationTrainer
    from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint, load_checkpoint
    from skillchain_torch.trainers.outputs.out_dir import _prepare_out
    from skillchain_torch.trainers.outputs.run_outputs import train_and_write

    run_dir = Path(run_dir)
    state = run_state(run_dir)
    if state == "done":
        return 0
    config = TrainConfig.load_json(run_dir / "config.json")  # (options: relative to the cwd)
    trainer = PopulationTrainer(config, out_dir=run_dir, num_threads=threads)
    if state == "partial":
        load_checkpoint(latest_checkpoint(run_dir), trainer)
    else:
        class _Parser:  # _prepare_out reports through a parser
            def error(self, message):
                raise ValueError(message)

        saved = (run_dir / "config.json").read_text()
        _prepare_out(_Parser(), run_dir, overwrite=True)
        (run_dir / "config.json").write_text(saved)
    return train_and_write(trainer, run_dir, quiet)  # (what the CLI's _run does, unparsed)


def experiment_spans(runs: int, jobs: int) -> list[tuple[int, int]]:
    """A run's blocks: one per job (batched steps are worth more than balancing,
    ``benchmarks/README.md``), as even as the agents allow.

    Example:
        >>> experiment_spans(100, 2), experiment_spans(3, 2), experiment_spans(1, 2)
        ([(0, 50), (50, 100)], [(0, 2), (2, 3)], [(0, 1)])
    """
    from skillchain_torch.trainers.distributed.blocks import block_spans

    return block_spans(runs, -(-runs // max(1, min(jobs, runs))))


@dataclass
class _Job:
    """A process to run: a block of an experiment, the merge of its blocks, or (``"run"``) an
    older study's interrupted run, finished in one process."""

    exp: Experiment
    kind: str  # "block", "merge" or "run"
    span: tuple[int, int] | None = None

    @property
    def label(self) -> str:
        return self.exp.name + (f"[{self.span[0]}-{self.span[1]}]" if self.span else
                                "" if self.kind == "run" else "[merge]")  # fmt: skip


def _launch(out: Path, job: _Job, wall: float = 0.0, jobs: int = 2) -> subprocess.Popen:
    # From the study's folder, where the given-options runs' options paths are relative to.
    cmd = [sys.executable, "-m", "skillchain_torch.trainers.study.reproduce", job.exp.name]
    if job.kind == "block":
        cmd += ["--block", f"{job.span[0]}-{job.span[1]}"]
    elif job.kind == "merge":
        cmd += ["--merge", "--wall", f"{wall:.3f}", "--jobs", str(jobs)]
    handle = open(out / f"{job.exp.name}.log", "a")
    handle.write(f"\n# {time.strftime('%Y-%m-%d %H:%M:%S')} (in {out}) {' '.join(cmd)}\n")
    handle.flush()
    return subprocess.Popen(cmd, stdout=handle, stderr=subprocess.STDOUT, cwd=out)


def _jobs_of(exp: Experiment, out: Path, jobs: int) -> list[_Job]:
    """What is left to do for ``exp`` (not done): its unfinished blocks, or its merge."""
    from skillchain_torch.trainers.distributed.blocks import DONE, SHARDING, ShardedRun
    from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint

    run_dir = out / exp.name
    if not (run_dir / SHARDING).is_file() and latest_checkpoint(run_dir) is not None:
        return [_Job(exp, "run")]  # an older study's one-process run, interrupted
    run_dir.mkdir(parents=True, exist_ok=True)
    if not (run_dir / "config.json").is_file():
        exp.config.save_json(run_dir / "config.json")
    if (run_dir / SHARDING).is_file():  # resumed: the blocks it was cut into
        run = ShardedRun.load(run_dir, exp.config)
    else:
        run = ShardedRun(exp.config, run_dir, experiment_spans(exp.config.runs, jobs))
        run.save(jobs)
    left = [_Job(exp, "block", span) for span in run.spans
            if not (run.block_dir(span) / DONE).is_file()]
    return left or [_Job(exp, "merge")]


def _finished(job: _Job, out: Path, code: int) -> bool:
    from skillchain_torch.trainers.distributed.blocks import DONE

    if job.kind == "block":
        a, b = job.span
        return code == 0 and (out / job.exp.name / "blocks" / f"{a}-{b}" / DONE).is_file()
    return code == 0 and run_state(out / job.exp.name) == "done"


def _record_timing(out: Path, started: float, names: list[str], complete: bool) -> None:
    """Append this invocation's wall time to ``out/timing.json``."""
    path = out / "timing.json"
    record = json.loads(path.read_text()) if path.is_file() else {"invocations": []}
    seconds = time.time() - started
    record["invocations"].append({
        "started": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(started)),
        "seconds": round(seconds, 1), "runs": names, "complete": complete})
    record["seconds"] = round(sum(i["seconds"] for i in record["invocations"]), 1)
    path.write_text(json.dumps(record, indent=1) + "\n")


def run_experiments(experiments: list[Experiment], out: str | Path, jobs: int = 2,
                    quiet: bool = False, poll: float = 2.0) -> dict[str, str]:  # fmt: skip
    """Run every experiment under ``out`` (blocks as jobs, ``jobs`` processes at a time),
    skipping the finished ones; returns each experiment's final state. A failed block stops
    its run and the run's dependants, reported by name (``RuntimeError`` once the others are
    done)."""
    from tqdm import tqdm

    from skillchain_torch.trainers.distributed.blocks import record_driver_wall

    out = Path(out)
    for exp in experiments:  # refuse a mismatch before anything starts
        _check_config(exp, out / exp.name)
    needed = {e.depends for e in experiments if e.depends}
    # Runs that others wait for go first (a stable sort keeps the study's order otherwise).
    waiting = sorted((e for e in experiments if run_state(out / e.name) != "done"),
                     key=lambda e: e.name not in needed)  # fmt: skip
    states = {e.name: "done" for e in experiments if run_state(out / e.name) == "done"}
    queue: list[_Job] = []
    left: dict[str, int] = {}  # jobs of each released experiment not finished yet
    first: dict[str, float] = {}  # when its first job started in this invocation
    running: dict[subprocess.Popen, _Job] = {}
    failed: list[str] = []
    clock = time.time()
    bar = tqdm(total=len(experiments), initial=len(states), desc="paper runs", unit="run",
               disable=quiet, dynamic_ncols=True)  # fmt: skip

    def release() -> None:
        for exp in list(waiting):
            dep = states.get(exp.depends) if exp.depends is not None else "done"
            if dep == "failed":
                waiting.remove(exp)
                states[exp.name] = "failed"
                failed.append(f"{exp.name} (its options' run {exp.depends} failed)")
                bar.update(1)
            elif dep == "done":
                waiting.remove(exp)
                todo = _jobs_of(exp, out, jobs)
                left[exp.name] = len(todo)
                queue.extend(todo)

    try:
        release()
        while queue or running:
            for proc, job in list(running.items()):
                code = proc.poll()
                if code is None:
                    continue
                del running[proc]
                name = job.exp.name
                if states.get(name) == "failed":
                    continue
                if not _finished(job, out, code):
                    states[name] = "failed"
                    failed.append(f"{job.label} (exit {code}; see {out / name}.log)")
                    queue[:] = [j for j in queue if j.exp.name != name]
                    bar.update(1)
                    continue
                left[name] -= 1
                if job.kind == "block" and left[name] == 0:  # merge next, before other blocks
                    left[name] = 1
                    queue.insert(0, _Job(job.exp, "merge"))
                elif job.kind != "block":
                    states[name] = "done"
                    bar.update(1)
            release()
            while queue and len(running) < jobs:
                job = queue.pop(0)
                name = job.exp.name
                first.setdefault(name, time.perf_counter())
                wall = time.perf_counter() - first[name]
                running[_launch(out, job, wall=wall, jobs=jobs)] = job
            bar.set_postfix_str(", ".join(j.label for j in running.values()) or "-")
            if running:
                time.sleep(poll)
    except KeyboardInterrupt:
        for proc in running:
            proc.send_signal(2)  # SIGINT: each block stops at a step and can be resumed
        for proc in running:
            proc.wait()
        bar.close()
        for name, start in first.items():  # the merge adds it to the run's wall time
            if states.get(name) != "done" and (out / name / "sharding.json").is_file():
                record_driver_wall(out / name, time.perf_counter() - start)
        _record_timing(out, clock, sorted(first), complete=False)
        raise
    bar.close()
    _record_timing(out, clock, sorted(first), complete=not failed)
    if failed:
        raise RuntimeError("runs failed: " + "; ".join(failed))
    return states


def reproduce_paper(out: str | Path, runs: int = 100, episodes: int = 250,
                    hard_runs: int | None = None,
                    hard_episodes: int | None = None, seed: int = 1000, jobs: int = 2,
                    instances=("simple", "hard"), quiet: bool = False,
                    report: bool = True, **reading) -> Path:  # fmt: skip
    """Run (or finish) every experiment, then write the figures and ``out/README.md``.

    ``hard_runs`` ``None``: ``runs`` on the second instance too.
    ``reading``: :class:`TrainConfig` fields every run takes instead of the defaults, e.g.
    ``preset="paper", slots=48`` for the study under every value the paper states::

        reproduce_paper("results/paper-preset", preset="paper", slots=48)
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    exps = paper_experiments(runs, episodes, hard_runs, hard_episodes, seed, instances, **reading)
    (out / "experiments.json").write_text(json.dumps(
        [{"name": e.name, "config": e.config.to_dict(), "depends": e.depends} for e in exps],
        indent=1) + "\n")  # fmt: skip
    run_experiments(exps, out, jobs=jobs, quiet=quiet)
    if report:
        from skillchain_torch.trainers.study.paper_report import write_report

        return write_report(out, [e.name for e in exps], quiet=quiet)
    return out


def _job_main(argv: list[str] | None = None) -> int:
    """One job of :func:`run_experiments`, in its own process, from the study's folder:
    ``RUN`` (an older study's one-process run), ``RUN --block a-b`` or ``RUN --merge``."""
    import argparse

    from skillchain_torch.trainers.distributed.block_merge import merge_blocks
    from skillchain_torch.trainers.distributed.block_run import run_block
    from skillchain_torch.trainers.distributed.blocks import DONE, ShardedRun, block_config

    parser = argparse.ArgumentParser(prog="python -m skillchain_torch.trainers.study.reproduce")
    parser.add_argument("run")
    parser.add_argument("--block", default=None, help="a-b: train agents [a, b)")
    parser.add_argument("--merge", action="store_true", help="merge the finished blocks")
    parser.add_argument("--wall", type=float, default=0.0, help="seconds since the first block")
    parser.add_argument("--jobs", type=int, default=2)
    args = parser.parse_args(argv)
    run_dir = Path(args.run)
    if args.block is None and not args.merge:
        return train_dir(run_dir)
    config = TrainConfig.load_json(run_dir / "config.json")
    if args.block is not None:
        a, b = (int(x) for x in args.block.split("-"))
        block_dir = run_dir / "blocks" / f"{a}-{b}"
        run_block(block_config(config, a, b, block_dir), block_dir)
        return 0
    run = ShardedRun.load(run_dir, config)
    records = {span: json.loads((run.block_dir(span) / DONE).read_text()) for span in run.spans}
    merge_blocks(run, records, args.jobs, args.wall)
    return 0


if __name__ == "__main__":  # one job of run_experiments, in its own process
    sys.exit(_job_main())
