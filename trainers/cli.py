"""The ``skillchain`` command line.

    skillchain train --agent flat --map pinball_simple_single --runs 20 --episodes 100 \\
        --seed 0 --out runs/flat
    skillchain train --resume runs/flat          # continue from the last checkpoint
    skillchain summarize runs/flat               # the table of returns per episode window
    skillchain train ... --workers 2             # agents in blocks on Ray workers (distributed.py)
    skillchain sweep grid.toml --out sweeps/x    # a grid of runs on Ray, then a summary (sweep.py)

``train`` writes ``DIR/config.json``, ``DIR/tb/`` (TensorBoard), ``DIR/checkpoints/``, and at
the end ``DIR/returns.npy`` (float64 [runs, episodes]), ``DIR/lengths.npy`` (int64),
``DIR/learning_curve.png`` and ``DIR/run_info.json`` (wall time, steps per second).
Skill-chaining runs also write ``DIR/options.pt`` (every agent's options, for ``--agent
given-options``), ``DIR/n_options.npy`` ([runs, episodes]: options held at each episode's
end), ``DIR/option_tree.json`` and ``DIR/option_trajectory.png`` (a greedy solution coloured by
option, as the paper's Figure 4b).
Invalid arguments exit with status 2 and a message.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import shutil
import sys
from pathlib import Path

from .agents import AGENTS
from .config import UNREAD_FIELDS, TrainConfig

__all__ = ["main", "build_parser"]

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
    "option_tree.json",
    "option_trajectory.png",
    "diverged.json",  # a diverged run's returns so far (PopulationTrainer.DIVERGED_OUTPUTS)
    "partial_returns.npy",
    "partial_lengths.npy",
    "blocks",  # a sharded run's (distributed.py): --overwrite must not reuse its blocks
    "sharding.json",
)
# Options that define the run; with --resume the saved config is used instead.
CONFIG_OPTIONS = (
    "agent",
    "map",
    "runs",
    "episodes",
    "seed",
    "alpha",
    "epsilon",
    "gamma",
    "order",
    "scale_step_size",
    "max_episode_steps",
    "checkpoint_every",
    "options",
    "options_agent",
    "slots",
    "initiation_bias",
    "initiation_centered",
    "gestation_positives",
    "initiation_start",
    "initiation_constrain",
    "one_class_fits",
    "failure_bootstrap",
    "keep_negatives",
    "intra_option_primitives",
    "option_interruption",
    "policy_start",
    "value_start",
    "value_bonus",
    "option_alpha",
    "completion_reward",
    "gestation",
    "convergence_threshold",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="skillchain", description="Skill chaining (Konidaris & Barto, 2009) on Pinball."
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    train = sub.add_parser(
        "train",
        help="train a population of agents",
        description="Train P independent agents for E episodes each.",
    )
    train.add_argument(
        "--agent", choices=sorted(AGENTS), default=None, help="agent type (default: flat)"
    )
    train.add_argument(
        "--map", default=None, help="Pinball map name (default: pinball_simple_single)"
    )
    train.add_argument("--runs", type=int, default=None, help="P, independent agents (default 1)")
    train.add_argument(
        "--episodes", type=int, default=None, help="E, episodes per agent (default 100)"
    )
    train.add_argument("--seed", type=int, default=None, help="agent p uses seed + p (default 0)")
    train.add_argument(
        "--alpha",
        type=float,
        default=None,
        help="step size (default: 0.001 on simple maps, 0.0005 on hard maps)",
    )
    train.add_argument("--epsilon", type=float, default=None, help="exploration (default 0.01)")
    train.add_argument("--gamma", type=float, default=None, help="discount (default 1)")
    train.add_argument(
        "--order",
        type=int,
        default=None,
        help="Fourier order (default: 4 on simple maps, 5 on hard maps)",
    )
    train.add_argument(
        "--scale-step-size",
        action="store_true",
        default=None,
        help="per-feature step sizes alpha / ||c|| (default off)",
    )
    train.add_argument(
        "--max-episode-steps",
        type=int,
        default=None,
        help="truncate episodes after this many steps (default: never)",
    )
    train.add_argument(
        "--options",
        default=None,
        help="OptionBank file (torch.save) for --agent given-options, e.g. from "
        "python -m skillchain_torch.agents.region_option OUT.pt",
    )
    train.add_argument(
        "--options-agent",
        type=_options_agent,
        default=None,
        metavar="N|each",
        help="for --agent given-options: start every agent with saved agent N's options "
        "(default 0), or 'each': agent p takes saved agent p's",
    )
    train.add_argument(
        "--slots",
        type=int,
        default=None,
        help="option slots per agent for --agent skill-chaining (default 12)",
    )
    train.add_argument(
        "--initiation-bias",
        type=float,
        default=None,
        help="intercept new initiation classifiers start from (default 0: true everywhere "
        "until the first fit, which starts from zero)",
    )
    train.add_argument(
        "--initiation-centered",
        action="store_const",
        const=True,
        default=None,
        help="initiation classifiers on features of 2s-1 instead of s",
    )
    train.add_argument(
        "--gestation-positives",
        type=int,
        default=None,
        metavar="N",
        help="reading: each time a gestating option's target fires, the last N states of the "
        "trajectory become positive examples (0: none; 250: the paper's 'within 250 steps')",
    )
    train.add_argument(
        "--initiation-start",
        choices=("everything", "biased", "fitted"),
        default=None,
        help="reading: the initiation set when gestation ends: true everywhere, true through "
        "--initiation-bias, or fitted on the gestation positives",
    )
    train.add_argument(
        "--initiation-constrain",
        choices=("learned", "start"),
        default=None,
        help="reading: the 0.1 distance constraint once the set is learned, or from the end "
        "of gestation",
    )
    train.add_argument(
        "--wait-for-both-classes",
        dest="one_class_fits",
        action="store_const",
        const=False,
        default=None,
        help="reading: fit an initiation set only once it holds both classes",
    )
    train.add_argument(
        "--keep-negatives",
        choices=("on", "off"),
        default=None,
        help="initiation-set stores never drop a failure to make room for a success's "
        "positives",
    )
    train.add_argument(
        "--intra-option-primitives",
        choices=("on", "off"),
        default=None,
        help="the top level's primitive values also learn from the steps options take "
        "(one-step Q-learning; default off: only from the agent's own primitive decisions, "
        "as the paper's SMDP Sarsa)",
    )
    train.add_argument(
        "--option-interruption",
        choices=("on", "off"),
        default=None,
        help="an executing option stops where it is no longer the top level's greedy decision "
        "(default off: options run to their end, as the paper's)",
    )
    train.add_argument(
        "--failure-bootstrap",
        choices=("decision", "primitives"),
        default=None,
        help="what a timed-out option execution's SMDP target bootstraps on: the next "
        "decision (Sarsa, the paper) or the best primitive at s'",
    )
    train.add_argument(
        "--policy-start",
        choices=("zero", "top-level"),
        default=None,
        help="how a new option's policy starts when it joins: zero weights updated off-policy "
        "in gestation, or the agent's own primitive values projected onto the option's basis",
    )
    train.add_argument(
        "--value-start",
        choices=("max-sample", "agent"),
        default=None,
        help="how Q(s, o) starts when an option joins: the best value sampled when its target "
        "fired in gestation, everywhere (the paper), or the agent's own max_a Q(s, a) fitted in "
        "its basis plus --value-bonus",
    )
    train.add_argument(
        "--value-bonus",
        type=float,
        default=None,
        help="added to Q(s, o) everywhere under --value-start agent (default 0)",
    )
    train.add_argument(
        "--option-alpha",
        type=float,
        default=None,
        help="the options' Q-learning step size after they join (default 0: an option keeps "
        "the policy it joins with; the paper: 0.0005)",
    )
    train.add_argument(
        "--gestation",
        type=int,
        default=None,
        help="episodes a new option gestates before it can be chosen (default 2; the paper: 10)",
    )
    train.add_argument(
        "--convergence-threshold",
        type=float,
        default=None,
        help="an initiation set is learned, and becomes a target event, when its weights moved "
        "less than this per episode twice in a row (default: the paper's 0.15)",
    )
    train.add_argument(
        "--completion-reward",
        type=float,
        default=None,
        help="added to an option's reward when its target fires (default 10000)",
    )
    train.add_argument(
        "--checkpoint-every",
        type=int,
        default=None,
        help="checkpoint every N episodes of the slowest agent (default 25)",
    )
    train.add_argument("--device", default=None, help="torch device (default cpu)")
    train.add_argument(
        "--threads", type=int, default=1, help="torch intra-op threads while training (default 1)"
    )
    train.add_argument("--out", type=Path, default=None, help="output directory")
    train.add_argument(
        "--resume",
        type=Path,
        metavar="DIR",
        default=None,
        help="continue the run in DIR from its last checkpoint",
    )
    train.add_argument(
        "--overwrite", action="store_true", help="replace the outputs of a previous run in --out"
    )
    train.add_argument(
        "--torch-only",
        action="store_true",
        help="run without the compiled agent kernels (slower; the same decisions, but sums "
        "rounded in torch's order: bit for bit the runs of versions before them)",
    )
    train.add_argument("--quiet", action="store_true", help="no progress bar")
    train.add_argument(
        "--workers",
        type=_positive,
        default=None,
        help="train the agents on N Ray workers in blocks, merged into --out bit for bit "
        "(default 1: this process; needs pip install skillchain_torch[ray])",
    )
    train.add_argument(
        "--block-size",
        type=_block_size,
        default=None,
        metavar="B",
        help="with --workers: agents per block, handed to workers as they free up, or "
        "'shrink' (each block 1/(2N) of the agents left) (default: one block per worker, which "
        "keeps the agents' steps batched)",
    )
    train.add_argument(
        "--ray-address",
        default=None,
        metavar="ADDR",
        help="with --workers: the Ray cluster to use (default: RAY_ADDRESS, else a local Ray "
        "of N CPUs)",
    )
    summary = sub.add_parser("summarize", help="print the returns table of a finished run")
    summary.add_argument("dir", type=Path, help="run directory")
    reproduce = sub.add_parser(
        "reproduce",
        help="run the paper's experiments and write their figures and report",
        description="Run the paper's experiments (flat, skill chaining and given options on "
        "both Pinball instances), then write the figures (4a-8) and DIR/README.md. Resumable: "
        "run it again to finish an interrupted study.",
    )
    reproduce.add_argument("what", choices=("paper",), help="the study to reproduce")
    reproduce.add_argument("--out", type=Path, required=True, help="output directory")
    reproduce.add_argument("--runs", type=_positive, default=100,
                           help="runs per agent on the first instance (default 100)")
    reproduce.add_argument("--episodes", type=_positive, default=250,
                           help="episodes per run (default 250)")
    reproduce.add_argument("--hard-runs", type=_positive, default=30,
                           help="runs per agent on the second instance (default 30)")
    reproduce.add_argument("--hard-episodes", type=_positive, default=None,
                           help="episodes per run on the second instance (default: --episodes)")
    reproduce.add_argument("--seed", type=int, default=1000,
                           help="agent p of every kind uses seed + p (default 1000)")
    reproduce.add_argument("--instances", nargs="+", choices=("simple", "hard"),
                           default=["simple", "hard"], help="which instances (default both)")
    reproduce.add_argument("--jobs", type=_positive, default=2,
                           help="runs in parallel, one process each (default 2)")
    reproduce.add_argument("--report-only", action="store_true",
                           help="write the report and figures from the finished runs only")
    reproduce.add_argument("--quiet", action="store_true", help="no progress bar")
    verify = sub.add_parser(
        "verify",
        help="re-run agents of a finished run alone and compare them bit for bit",
        description="Re-run the given agents of RUN_DIR one at a time from its config.json and "
        "compare their returns and lengths with the run's arrays bit for bit. Exit 0 only if "
        "every agent matches.",
    )
    verify.add_argument("dir", type=Path, help="run directory")
    verify.add_argument("--agents", type=int, nargs="+", required=True, help="agent indices")
    sweep = sub.add_parser(
        "sweep",
        help="run a grid of configurations on Ray and compare them",
        description="Run every cell of SPEC's grid (agents x maps x TrainConfig fields x "
        "seeds) as a run directory OUT/<cell>/, the cells' blocks of agents sharing one Ray "
        "pool; complete cells are skipped on a re-run. Then write OUT/summary.md (window "
        "means with 95% intervals) and OUT/summary.png. Needs pip install "
        "skillchain_torch[ray].",
    )
    sweep.add_argument("spec", type=Path, help="sweep spec, TOML (or YAML with PyYAML)")
    sweep.add_argument("--out", type=Path, default=None,
                       help="output directory (default: the spec's out, else its name)")
    sweep.add_argument("--workers", type=_positive, default=None,
                       help="Ray workers (default: the spec's workers, else every CPU)")
    sweep.add_argument("--block-size", type=_block_size, default=None, metavar="B",
                       help="agents per block (default: one block per worker, as train --workers)")
    sweep.add_argument("--ray-address", default=None, metavar="ADDR",
                       help="the Ray cluster to use (default: RAY_ADDRESS, else a local Ray)")
    sweep.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.commands = {"train": train, "summarize": summary, "reproduce": reproduce,
                       "verify": verify, "sweep": sweep}
    return parser


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def _options_agent(text: str):
    if text == "each":
        return "each"
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected an agent index or 'each', got {text!r}"
        ) from None


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    command = parser.commands[args.command]  # errors print this command's usage
    if args.command == "summarize":
        from .summary import summarize_dir

        try:
            print(summarize_dir(args.dir))
        except ValueError as err:
            command.error(str(err))
        return 0
    if args.command == "reproduce":
        return _reproduce(command, args)
    if args.command == "verify":
        return _verify(command, args)
    if args.command == "sweep":
        return _sweep(command, args)
    return _train(command, args)


def _reproduce(parser, args) -> int:
    from .reproduce import reproduce_paper

    try:
        if args.report_only:
            from .paper_report import write_report

            path = write_report(args.out, quiet=args.quiet)
        else:
            path = reproduce_paper(args.out, runs=args.runs, episodes=args.episodes,
                                   hard_runs=args.hard_runs, hard_episodes=args.hard_episodes,
                                   seed=args.seed, jobs=args.jobs, instances=args.instances,
                                   quiet=args.quiet)  # fmt: skip
    except (ValueError, RuntimeError) as err:
        parser.error(str(err))
    except KeyboardInterrupt:
        print("\ninterrupted; continue with the same command", file=sys.stderr)
        return 130
    print(f"report: {path}")
    return 0


def _sweep(parser, args) -> int:
    from .distributed import require_ray
    from .sweep import run_sweep

    try:
        require_ray("skillchain sweep")
    except ImportError as err:
        parser.error(str(err))
    try:
        result = run_sweep(args.spec, out=args.out, workers=args.workers,
                           block_size=args.block_size, address=args.ray_address,
                           quiet=args.quiet)  # fmt: skip
    except ValueError as err:
        parser.error(_one_line(err))
    except RuntimeError as err:  # a block failed (a diverged learner)
        _fail(parser, _one_line(err) + "; fix it and run the same command again")
    except KeyboardInterrupt:
        print("\ninterrupted; continue with the same command", file=sys.stderr)
        return 130
    if not args.quiet:
        print(result["table"])
    print(f"{len(result['ran'])} cells run, {len(result['skipped'])} skipped (complete); "
          f"summary: {result['summary']}")
    return 0


def _verify(parser, args) -> int:
    from .verify import verify_run

    try:
        results = verify_run(args.dir, args.agents, progress=True)
    except ValueError as err:
        parser.error(str(err))
    ok = all(r["match"] for r in results)
    print(f"{args.dir}: {'match' if ok else 'MISMATCH'} "
          f"({sum(r['match'] for r in results)} of {len(results)} agents identical)")
    return 0 if ok else 1


def _flag(name: str) -> str:
    """The ``skillchain train`` flag of a config field."""
    return "--wait-for-both-classes" if name == "one_class_fits" else "--" + name.replace("_", "-")


def _given(args) -> list[str]:
    """The config fields set on the command line (``--device`` included)."""
    names = [n for n in CONFIG_OPTIONS if getattr(args, n) is not None]
    return names + (["device"] if args.device is not None else [])


def _flag_message(err: ValueError, given) -> str:
    """``err``'s message led by the flags of the fields at fault that were given on the
    command line (``--seed: seed must be ...``)."""
    flags = [_flag(name) for name in getattr(err, "fields", ()) if name in given]
    return ", ".join(flags) + ": " + str(err) if flags else str(err)


def _config_from_args(parser, args) -> TrainConfig:
    given = {name: getattr(args, name) for name in CONFIG_OPTIONS}
    given = {k: v for k, v in given.items() if v is not None}
    if given.get("options_agent") == "each":
        given["options_agent"] = None
    for name in ("keep_negatives", "intra_option_primitives", "option_interruption"):
        if name in given:
            given[name] = given[name] == "on"
    if args.device is not None:
        given["device"] = args.device
    agent = given.get("agent", TrainConfig().agent)
    unread = [n for n in UNREAD_FIELDS.get(agent, ()) if n in given]
    if unread:
        readers = {n: [a for a in sorted(AGENTS) if n not in UNREAD_FIELDS.get(a, ())]
                   for n in unread}
        parser.error(f"--agent {agent} does not read " + ", ".join(
            f"{_flag(n)} (only {' or '.join(readers[n]) or 'no agent'})" for n in unread)
            + "; leave them out or choose that --agent")
    try:
        return TrainConfig(**given).validate().resolved()
    except ValueError as err:
        parser.error(_flag_message(err, given))


def _one_line(message) -> str:
    """``message`` on one line (torch's and numpy's errors span several)."""
    return " ".join(str(message).split())


def _fail(parser, message: str) -> None:
    """Exit with status 2 and one line (for failures that are not about the arguments' form)."""
    parser.exit(2, f"{parser.prog}: error: {message}\n")


def _check_out(parser, out: Path, overwrite: bool) -> None:
    """Refuse an ``--out`` that cannot take the run, writing nothing."""
    try:
        if out.exists() and not out.is_dir():
            parser.error(f"--out {out} exists and is not a directory")
        if out.is_dir():
            if any(out.iterdir()) and not overwrite:
                parser.error(
                    f"--out {out} exists and is not empty; pass --resume {out} to continue "
                    "it or --overwrite to replace it"
                )
            if not os.access(out, os.W_OK | os.X_OK):
                parser.error(f"--out {out}: the directory is not writable")
            return
        parent = next(p for p in out.absolute().parents if p.exists())
    except OSError as err:
        parser.error(f"--out {out}: cannot use it ({err.strerror or err})")
    if not parent.is_dir():
        parser.error(f"--out {out}: {parent} is a file, so no directory can be created under it")
    if not os.access(parent, os.W_OK | os.X_OK):
        parser.error(f"--out {out}: cannot create it, {parent} is not writable")


def _prepare_out(parser, out: Path, overwrite: bool) -> Path | None:
    """Create ``out`` (or clear a previous run's outputs from it, with ``overwrite``); returns
    the topmost directory this call created (``None`` if ``out`` existed)."""
    missing = [p for p in (out.absolute(), *out.absolute().parents) if not p.exists()]
    created = missing[-1] if missing else None
    try:
        if out.is_dir() and any(out.iterdir()) and overwrite:
            _remove_outputs(out, strict=True)
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        _remove_created(created)
        _fail(parser, f"--out {out}: cannot write there ({err.strerror or err})")
    return created


def _remove_created(created: Path | None) -> None:
    if created is not None:
        shutil.rmtree(created, ignore_errors=True)


def _remove_outputs(out: Path, strict: bool = False) -> None:
    """Remove a run's outputs (``OUTPUTS``) from ``out``; ``strict``: raise ``OSError``s."""
    for name in OUTPUTS:
        target = out / name
        try:
            if target.is_dir():
                shutil.rmtree(target)
            elif target.exists():
                target.unlink()
        except OSError:
            if strict:
                raise


def _write_error(err: BaseException) -> str | None:
    """A one-line reason if ``err`` is a failure to write a file (a full disk, a read-only or
    removed directory; torch.save reports its own as RuntimeError), else ``None``."""
    if isinstance(err, OSError):
        where = f" ({err.filename})" if getattr(err, "filename", None) else ""
        return f"{err.strerror or err}{where}"
    text = str(err)
    if isinstance(err, RuntimeError) and ("PytorchStreamWriter" in text
                                          or "file write failed" in text):
        return " ".join(text.split())[:200]
    return None


# torch.set_num_threads takes a C int; more threads than 4 per core only wait for each other.
MAX_THREADS_PER_CPU = 4


def _train(parser, args) -> int:
    """Everything is checked (arguments, the saved config, --out, building the agents) before
    anything is written, so a refused command leaves nothing that blocks the corrected one."""
    from .checkpoint import latest_checkpoint, resume_checkpoint
    from .population import PopulationTrainer

    max_threads = MAX_THREADS_PER_CPU * (os.cpu_count() or 1)
    if args.threads < 1:
        parser.error(f"--threads must be >= 1, got {args.threads}")
    if args.threads > max_threads:
        parser.error(f"--threads must be at most {max_threads} ({MAX_THREADS_PER_CPU} per CPU "
                     f"of this machine), got {args.threads}")  # fmt: skip
    source_commit()  # read as the run starts: the code this process runs
    native = False if args.torch_only else None
    created = None
    sharded = _check_sharding(parser, args)
    if args.resume is not None:
        out = args.resume
        given = [_flag(n) for n in CONFIG_OPTIONS if getattr(args, n) is not None]
        given += ["--out"] * (args.out is not None) + ["--overwrite"] * args.overwrite
        if given:
            parser.error(f"--resume continues with the saved config, writing into {out}; do "
                         f"not pass " + ", ".join(given))  # fmt: skip
        path = out / "config.json"
        if not path.is_file():
            parser.error(f"--resume {out}: no config.json there (not a run directory)")
        try:
            config = TrainConfig.load_json(path)
        except ValueError as err:
            parser.error(str(err))
        if args.device is not None:
            config = dataclasses.replace(config, device=args.device)
        try:
            config.validate()
        except ValueError as err:
            if getattr(err, "fields", ()) == ("device",) and args.device is not None:
                parser.error(_flag_message(err, ["device"]))
            hint = " (resume with --device cpu)" if "device" in getattr(err, "fields", ()) else ""
            parser.error(f"{path}: {err}{hint}")
        if sharded or (out / "sharding.json").is_file():
            return _train_sharded(parser, args, config, out, native, resume=True)
        checkpoint = latest_checkpoint(out)
        if checkpoint is None:
            parser.error(f"--resume {out}: no checkpoint under {out / 'checkpoints'}")
        try:
            trainer = PopulationTrainer(config, out_dir=out, num_threads=args.threads,
                                        native=native)
            checkpoint = resume_checkpoint(out, trainer)  # damaged newer ones: the one before
        except ValueError as err:
            parser.error(_one_line(err))
        if not args.quiet:
            print(f"resuming {out} from {checkpoint.name}", file=sys.stderr)
    else:
        if args.out is None:
            parser.error("--out DIR is required (or --resume DIR)")
        config = _config_from_args(parser, args)
        out = args.out
        _check_out(parser, out, args.overwrite)
        try:
            trainer = PopulationTrainer(config, out_dir=out, num_threads=args.threads,
                                        native=native)
        except ValueError as err:
            parser.error(_one_line(_flag_message(err, _given(args))))
        created = _prepare_out(parser, out, args.overwrite)
        try:
            config.save_json(out / "config.json")
        except OSError as err:
            _remove_created(created)
            _fail(parser, f"--out {out}: cannot write there ({_write_error(err)})")
        if sharded:
            return _train_sharded(parser, args, config, out, native, resume=False)
    return _run(trainer, out, quiet=args.quiet, parser=parser, created=created)


def _block_size(text: str) -> int | str:
    """``--block-size``: a number of agents, or ``shrink``."""
    if text == "shrink":
        return text
    try:
        int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of agents or 'shrink', got "
                                         f"{text!r}") from None
    return _positive(text)


def _check_sharding(parser, args) -> bool:
    """Check --workers, --block-size and --ray-address together (each alone is checked by its
    argparse type); True for a sharded run (N > 1)."""
    sharded = (args.workers or 1) > 1
    resumed = args.resume is not None and (args.resume / "sharding.json").is_file()
    if not (sharded or resumed):
        for flag, value in (("--block-size", args.block_size),
                            ("--ray-address", args.ray_address)):
            if value is not None:
                parser.error(f"{flag} needs --workers N with N > 1")
    if sharded and args.resume is not None and not resumed:
        parser.error(f"--resume {args.resume} is a one-process run and resumes as one; do not "
                     f"pass --workers")
    if args.resume is not None and args.block_size is not None:
        parser.error("--resume keeps the run's blocks; do not pass --block-size")
    runs = args.runs if args.runs is not None else 1  # TrainConfig's default
    if args.resume is None and isinstance(args.block_size, int) and args.block_size > runs > 0:
        parser.error(f"--block-size must be at most --runs ({runs}), got {args.block_size}")
    if sharded or resumed:
        from .distributed import require_ray

        try:
            require_ray("--workers" if sharded else f"--resume {args.resume} (a sharded run)")
        except ImportError as err:
            parser.error(str(err))
    return sharded


def _train_sharded(parser, args, config, out: Path, native, resume: bool) -> int:
    """Train ``config``'s agents in blocks on Ray workers and merge them into ``out``."""
    import time

    from .distributed import ShardedRun, plan_blocks, record_driver_wall, run_sharded

    if resume:
        run = ShardedRun.load(out, config)
        saved = json.loads((out / "sharding.json").read_text())["workers"]
        workers = args.workers or saved
    else:
        workers = args.workers
        run = ShardedRun(config, out, plan_blocks(config.runs, workers, args.block_size))
        run.save(workers)
    clock = time.perf_counter()
    try:
        [info] = run_sharded([run], workers, address=args.ray_address, threads=args.threads,
                             native=native, quiet=args.quiet)
    except KeyboardInterrupt:
        record_driver_wall(out, time.perf_counter() - clock)
        print(f"\ninterrupted; continue with: skillchain train --resume {out}", file=sys.stderr)
        return 130
    except RuntimeError as err:
        record_driver_wall(out, time.perf_counter() - clock)
        _fail(parser, _one_line(err) + f"; once fixed, continue with: skillchain train "
                                       f"--resume {out}")
    if not args.quiet:
        print(f"done: {info['agent_steps']:,} agent steps in {info['wall_time_s']:.1f} s on "
              f"{workers} workers ({info['blocks']} blocks); outputs in {out}", file=sys.stderr)
    return 0


def _run(trainer, out: Path, quiet: bool, parser=None, created: Path | None = None) -> int:
    """Train and write the outputs; a failure to write (a full disk, a read-only directory)
    exits with status 2 and one line, removing ``created`` (the directory this command made)
    when it holds no checkpoint to resume from."""
    try:
        return _train_and_write(trainer, out, quiet)
    except FloatingPointError as err:  # a learner diverged; the trainer saved what it had
        if parser is None:
            raise
        _fail(parser, _one_line(err))
    except (OSError, RuntimeError) as err:
        reason = _write_error(err)
        if reason is None or parser is None:
            raise
    from .checkpoint import latest_checkpoint

    if latest_checkpoint(out) is not None:
        hint = f"; once it can be written, continue with: skillchain train --resume {out}"
    else:  # nothing to resume: leave nothing that would refuse the same command again
        _remove_created(created)
        if created is None:
            _remove_outputs(out)
        hint = "; nothing to resume (no checkpoint was written), run the same command again"
    _fail(parser, f"cannot write the run's outputs in {out}: {reason}{hint}")


def _interrupted(out: Path, every: int) -> str:
    """What to do after Ctrl-C: resume from a checkpoint, or start again if none was written."""
    from .checkpoint import latest_checkpoint

    if latest_checkpoint(out) is not None:
        return f"\ninterrupted; continue with: skillchain train --resume {out}"
    when = f"every {every} episodes" if every else "disabled by --checkpoint-every 0"
    return (f"\ninterrupted before the first checkpoint ({when}); nothing to resume, run the "
            f"same command again with --overwrite")


def _train_and_write(trainer, out: Path, quiet: bool) -> int:
    import torch

    from .logging import TensorBoardHook
    from .plots import save_learning_curve
    from .progress import ProgressBar

    tb = TensorBoardHook.for_run(trainer, out)
    tb.register(trainer)
    discovery = None
    if getattr(trainer.agent, "discovery", None) is not None:
        from .discovery_log import DiscoveryLog

        discovery = DiscoveryLog(tb.logger)
        discovery.register(trainer)
    bar = ProgressBar(disable=quiet)
    bar.register(trainer)
    try:
        trainer.train()
    except KeyboardInterrupt:
        bar.close()
        tb.close()
        print(_interrupted(out, trainer.config.checkpoint_every), file=sys.stderr)
        return 130
    except FloatingPointError:  # a learner diverged: _run reports it
        bar.close()
        tb.close()
        raise
    tb.close()
    trainer.write_results(out)
    if discovery is not None:
        _write_discovery(trainer, discovery, out)
    cfg = trainer.config
    save_learning_curve(
        trainer.returns,
        out / "learning_curve.png",
        title=f"{cfg.agent} on {cfg.map} ({cfg.runs} runs)",
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


def _write_discovery(trainer, discovery, out: Path) -> None:
    """``options.pt`` (every agent's bank), ``n_options.npy`` and ``option_tree.json``."""
    import numpy as np

    from .discovery_log import option_tree

    trainer.agent.bank.save(out / "options.pt")
    np.save(out / "n_options.npy", discovery.n_options)
    (out / "option_tree.json").write_text(json.dumps(option_tree(trainer.agent), indent=1) + "\n")
    # Figure 4b: the best greedy solution through options, among the eight agents that hold
    # the most options (ties: the best last return).
    import torch

    from .option_trajectory import best_greedy_trajectory, save_option_trajectory

    held = trainer.agent.bank.live().sum(-1).cpu().numpy()
    last = np.nan_to_num(trainer.returns[:, -1], nan=-np.inf)
    order = sorted(range(len(held)), key=lambda p: (-held[p], -last[p]))[:8]
    # The replays are many tiny torch calls: at torch's default threads they ran ~12x slower on
    # a busy machine than at the trainer's one thread (a sharded run's workers draw at 1).
    threads = torch.get_num_threads()
    torch.set_num_threads(trainer.num_threads or threads)
    try:
        run = best_greedy_trajectory(trainer.agent, trainer.config.map, agents=order)
    finally:
        torch.set_num_threads(threads)
    save_option_trajectory(run, trainer.config.map, out / "option_trajectory.png")


if __name__ == "__main__":
    sys.exit(main())
