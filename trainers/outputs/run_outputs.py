"""What ``skillchain train`` writes for a run: the training loop with its TensorBoard log and
progress bar, then the arrays, figures and ``run_info.json``.

``OUTPUTS`` names every file a run may write (``--overwrite`` removes them, and only them);
:func:`source_commit` is the code a run came from, read once as the process starts.

Example:
    >>> "returns.npy" in OUTPUTS and "checkpoints" in OUTPUTS
    True
"""

from __future__ import annotations

import json
import platform
import sys
import time
from pathlib import Path

from skillchain_torch.trainers.loop.user_agent import agent_label

__all__ = ["OUTPUTS", "train_and_write", "source_commit", "write_discovery"]

OUTPUTS = (
    "returns.npy",
    "lengths.npy",
    "config.json",
    "run_info.json",
    "learning_curve.png",
    "tb",
    "checkpoints",
    "options.pt",
    "n_options.npy",
    "option_outcomes.npy",
    "option_tree.json",
    "option_tree.png",
    "option_trajectory.png",
    "diverged.json",  # a diverged run's returns so far (PopulationTrainer.DIVERGED_OUTPUTS)
    "partial_returns.npy",
    "partial_lengths.npy",
    "blocks",  # a sharded run's (blocks.py): --overwrite must not reuse its blocks
    "sharding.json",
)


def _interrupted(out: Path, every: int, user_agent: bool = False) -> str:
    """What to do after Ctrl-C: resume from a checkpoint, or start again if none was written."""
    from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint

    if user_agent:  # built in Python: the command line cannot rebuild it
        return (f"\ninterrupted; continue in Python: resume_checkpoint({str(out)!r}, "
                f"PopulationTrainer(config, out_dir={str(out)!r}, agent=agent)), then "
                f"train_and_write again")
    if latest_checkpoint(out) is not None:
        return f"\ninterrupted; continue with: skillchain train --resume {out}"
    when = f"every {every} episodes" if every else "disabled by --checkpoint-every 0"
    return (f"\ninterrupted before the first checkpoint ({when}); nothing to resume, run the "
            f"same command again with --overwrite")


def train_and_write(trainer, out: str | Path, quiet: bool = False) -> int:
    """Train ``trainer`` with the CLI's monitoring (TensorBoard under ``out/tb``, the discovery
    log, a progress bar) and write every output ``skillchain train`` writes into ``out``; returns
    the command's exit status (0; 130 after Ctrl-C, with how to resume). The same call for an
    agent of your own (``PopulationTrainer(config, out_dir=out, agent=agent)``).

    Example (a few seconds)::

        trainer = PopulationTrainer(TrainConfig(runs=2, episodes=3), out_dir="runs/mine")
        train_and_write(trainer, "runs/mine")   # returns.npy, learning_curve.png, tb/, ...
    """
    import torch

    from skillchain_torch.trainers.outputs.logging import TensorBoardHook
    from skillchain_torch.trainers.outputs.plots import save_learning_curve
    from skillchain_torch.trainers.outputs.progress import ProgressBar

    out = Path(out)
    tb = TensorBoardHook.for_run(trainer, out)
    tb.register(trainer)
    discovery = None
    if getattr(trainer.agent, "discovery", None) is not None:
        from skillchain_torch.trainers.outputs.discovery_log import DiscoveryLog

        discovery = DiscoveryLog(tb.logger)
        discovery.register(trainer)
    bar = ProgressBar(disable=quiet)
    bar.register(trainer)
    try:
        trainer.train()
    except KeyboardInterrupt:
        bar.close()
        tb.close()
        print(_interrupted(trainer.out_dir or out, trainer.config.checkpoint_every,
                           getattr(trainer, "user_agent", False)), file=sys.stderr)
        return 130
    except Exception:  # a diverged learner, a full disk: _run reports it
        bar.close()
        try:  # stop the event writer's thread before _run removes the files it writes to
            tb.close()
        except OSError:
            pass  # the disk that failed the run may fail the last flush too: report the first
        raise
    tb.close()
    clock = time.perf_counter()
    trainer.write_results(out)
    if discovery is not None:
        write_discovery(trainer, discovery, out)
    cfg = trainer.config
    save_learning_curve(
        trainer.returns,
        out / "learning_curve.png",
        title=f"{agent_label(trainer)} on {cfg.env_name} ({cfg.runs} runs)",
        reference=None if cfg.agent == "flat" else committed_flat(cfg),
    )
    info = {
        "wall_time_s": trainer.elapsed,
        "agent_steps": trainer.agent_steps,
        "agent_steps_per_second": trainer.steps_per_second(),
        "torch": torch.__version__,
        "threads": trainer.num_threads,
        "compiled_agent": bool(getattr(trainer.agent, "native", False)),
        "machine": platform.processor() or platform.machine(),
        "commit": source_commit(),
        "seconds": _seconds(trainer, tb, discovery, time.perf_counter() - clock),
    }
    (out / "run_info.json").write_text(json.dumps(info, indent=2) + "\n")
    if not quiet:
        mean_last = float(trainer.returns[:, -1].mean())
        print(
            f"done: {trainer.agent_steps:,} agent steps in {trainer.elapsed:.1f} s "
            f"({trainer.steps_per_second():,.0f}/s); mean return of the last episode "
            f"{mean_last:,.1f}; outputs in {out}",
            file=sys.stderr,
        )
    return 0


def _seconds(trainer, tb, discovery, outputs: float) -> dict:
    """Where the run's wall time went, so that the cost of watching a run is measurable
    without a profiler (issue 29: monitoring and figures at most 10% of the command).
    ``train`` includes the hooks; ``outputs`` is everything written after training (arrays,
    ``options.pt``, the figures with their greedy replays)."""
    monitor = tb.option_monitor.seconds if tb.option_monitor is not None else 0.0
    hooks = {"option_monitor": monitor, "tensorboard": tb.seconds,
             "discovery_log": discovery.seconds if discovery is not None else 0.0}
    watched = sum(hooks.values()) + outputs
    return {"train": trainer.elapsed, **hooks, "outputs": outputs,
            "monitoring_and_outputs": watched}


def source_commit() -> str | None:
    """The git commit of the installed source (``+dirty`` when it has uncommitted changes),
    or ``None`` outside a git checkout: recorded in ``run_info.json`` so a published run says
    which code made it.

    Read once per process, at the first call (``skillchain train`` calls it as it starts): a
    run takes hours, and a commit made meanwhile is not the code it runs. A resumed run
    records the commit of the invocation that finished it."""
    global _COMMIT
    if _COMMIT is _UNREAD:
        _COMMIT = _read_commit()
    return _COMMIT


_UNREAD = object()
_COMMIT: object = _UNREAD


def _read_commit() -> str | None:
    import subprocess

    root = Path(__file__).resolve().parent.parent
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True,
                              text=True, timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--",
                                "skillchain_torch", "envs", "trainers"], capture_output=True,
                               text=True, timeout=10, check=True).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return head + ("+dirty" if dirty else "")


def committed_flat(config) -> tuple[str, object] | None:
    """``(label, returns)`` of the committed flat study on ``config``'s Pinball map
    (``results/paper/<instance>/flat``, beside the package in a clone), or ``None``."""
    import numpy as np

    if config.env is not None:
        return None
    root = Path(__file__).resolve().parents[2] / "results" / "paper"
    for folder in (root / "simple" / "flat", root / "hard" / "flat"):
        try:
            saved = json.loads((folder / "config.json").read_text())
            if saved.get("map") == config.map:
                returns = np.load(folder / "returns.npy")
                return (f"flat Sarsa, results/paper ({returns.shape[0]} runs)", returns)
        except (OSError, ValueError):
            continue
    return None


def write_discovery(trainer, discovery, out: Path) -> None:
    """``options.pt`` (every agent's bank), ``n_options.npy``, ``option_outcomes.npy``,
    ``option_tree.json`` and its figure ``option_tree.png``."""
    import numpy as np

    from skillchain_torch.trainers.outputs.discovery_log import option_tree
    from skillchain_torch.trainers.outputs.option_trajectory import figure_candidates

    trainer.agent.bank.save(out / "options.pt")
    np.save(out / "n_options.npy", discovery.n_options)
    np.save(out / "option_outcomes.npy", discovery.outcomes)
    tree = option_tree(trainer.agent, discovery.slot_outcomes)
    (out / "option_tree.json").write_text(json.dumps(tree, indent=1) + "\n")
    from skillchain_torch.trainers.outputs.tree_figure import save_option_tree

    save_option_tree(tree, out / "option_tree.png")
    if trainer.config.env is not None:  # Figure 4b off Pinball: observation dims 0 and 1
        from skillchain_torch.trainers.outputs.env_trajectory import (
            best_env_trajectory,
            save_env_trajectory,
        )

        order = figure_candidates(trainer.agent.bank.live().sum(-1).cpu().numpy())
        run = best_env_trajectory(trainer.agent, trainer.config.env, agents=order, tries=1,
                                  obs_bounds=trainer.config.obs_bounds)  # fmt: skip
        save_env_trajectory(run, out / "option_trajectory.png")
        return
    # Figure 4b: the best greedy solution through options, among figure_candidates' eight.
    import torch

    from skillchain_torch.trainers.outputs.option_trajectory import (
        best_greedy_trajectory,
        save_option_trajectory,
    )

    order = figure_candidates(trainer.agent.bank.live().sum(-1).cpu().numpy(),
                              trainer.returns[:, -1])  # fmt: skip
    # The replays are many tiny torch calls: at torch's default threads they ran ~12x slower on
    # a busy machine than at the trainer's one thread (a sharded run's workers draw at 1).
    threads = torch.get_num_threads()
    torch.set_num_threads(trainer.num_threads or threads)
    try:
        run = best_greedy_trajectory(trainer.agent, trainer.config.map, agents=order)
    finally:
        torch.set_num_threads(threads)
    save_option_trajectory(run, trainer.config.map, out / "option_trajectory.png")

