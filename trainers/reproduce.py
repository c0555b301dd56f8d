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
of different kinds are paired. Runs execute as separate processes, ``--jobs`` at a time (both
cores of a 2-core machine by default); a given-options run waits for its skill-chaining run.
Then :mod:`.paper_report` writes ``DIR/README.md`` (tables with 95% intervals, the paper's
claims checked) and the figures (4a-8, :mod:`.paper_figures`).

Resumable: a finished run (``run_info.json``) is kept, an interrupted one continues from its
last checkpoint, a run never started begins; a run directory whose config differs from the one
asked for is refused by name. Each run's log is ``DIR/<instance>/<agent>.log``.

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

from .config import TrainConfig

__all__ = ["Experiment", "paper_experiments", "run_state", "run_experiments", "train_dir",
           "INSTANCES"]  # fmt: skip

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


def paper_experiments(runs: int = 100, episodes: int = 250, hard_runs: int = 30,
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
        n = runs if instance == "simple" else hard_runs
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
    from .checkpoint import latest_checkpoint

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
    from .checkpoint import latest_checkpoint, load_checkpoint
    from .cli import _prepare_out, _run
    from .population import PopulationTrainer

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
    return _run(trainer, run_dir, quiet=quiet)


def _launch(out: Path, name: str) -> subprocess.Popen:
    # From the study's folder, where the given-options runs' options paths are relative to.
    cmd = [sys.executable, "-m", "skillchain_torch.trainers.reproduce", name]
    handle = open(out / f"{name}.log", "a")
    handle.write(f"\n# {time.strftime('%Y-%m-%d %H:%M:%S')} (in {out}) {' '.join(cmd)}\n")
    handle.flush()
    return subprocess.Popen(cmd, stdout=handle, stderr=subprocess.STDOUT, cwd=out)


def run_experiments(experiments: list[Experiment], out: str | Path, jobs: int = 2,
                    quiet: bool = False, poll: float = 2.0) -> dict[str, str]:  # fmt: skip
    """Run every experiment under ``out`` (``jobs`` processes at a time), skipping the finished
    ones; returns each experiment's final state. A failed run stops its dependants and is
    reported by name (``RuntimeError`` once the others are done)."""
    from tqdm import tqdm

    out = Path(out)
    for exp in experiments:  # refuse a mismatch before anything starts
        _check_config(exp, out / exp.name)
    pending = [e for e in experiments if run_state(out / e.name) != "done"]
    states = {e.name: "done" for e in experiments if e not in pending}
    running: dict[str, subprocess.Popen] = {}
    failed: list[str] = []
    bar = tqdm(total=len(experiments), initial=len(states), desc="paper runs", unit="run",
               disable=quiet, dynamic_ncols=True)  # fmt: skip
    try:
        while pending or running:
            for name, proc in list(running.items()):
                code = proc.poll()
                if code is None:
                    continue
                del running[name]
                ok = code == 0 and run_state(out / name) == "done"
                states[name] = "done" if ok else "failed"
                if not ok:
                    failed.append(f"{name} (exit {code}; see {out / name}.log)")
                bar.update(1)
            for exp in list(pending):
                if len(running) >= jobs:
                    break
                if exp.depends is not None and states.get(exp.depends) != "done":
                    if states.get(exp.depends) == "failed":
                        pending.remove(exp)
                        states[exp.name] = "failed"
                        failed.append(f"{exp.name} (its options' run {exp.depends} failed)")
                        bar.update(1)
                    continue
                run_dir = out / exp.name
                run_dir.mkdir(parents=True, exist_ok=True)
                if not (run_dir / "config.json").is_file():
                    exp.config.save_json(run_dir / "config.json")
                running[exp.name] = _launch(out, exp.name)
                pending.remove(exp)
            bar.set_postfix_str(", ".join(running) or "-")
            if running:
                time.sleep(poll)
    except KeyboardInterrupt:
        for proc in running.values():
            proc.send_signal(2)  # SIGINT: each run stops at a step and can be resumed
        for proc in running.values():
            proc.wait()
        bar.close()
        raise
    bar.close()
    if failed:
        raise RuntimeError("runs failed: " + "; ".join(failed))
    return states


def reproduce_paper(out: str | Path, runs: int = 100, episodes: int = 250, hard_runs: int = 30,
                    hard_episodes: int | None = None, seed: int = 1000, jobs: int = 2,
                    instances=("simple", "hard"), quiet: bool = False,
                    report: bool = True) -> Path:  # fmt: skip
    """Run (or finish) every experiment, then write the figures and ``out/README.md``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    exps = paper_experiments(runs, episodes, hard_runs, hard_episodes, seed, instances)
    (out / "experiments.json").write_text(json.dumps(
        [{"name": e.name, "config": e.config.to_dict(), "depends": e.depends} for e in exps],
        indent=1) + "\n")  # fmt: skip
    run_experiments(exps, out, jobs=jobs, quiet=quiet)
    if report:
        from .paper_report import write_report

        return write_report(out, [e.name for e in exps], quiet=quiet)
    return out


if __name__ == "__main__":  # one run directory, in its own process (run_experiments)
    sys.exit(train_dir(sys.argv[1]))
