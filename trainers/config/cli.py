"""The ``skillchain`` command line.

    skillchain train --agent flat --map pinball_simple_single --runs 20 --episodes 100 \\
        --seed 0 --out runs/flat
    skillchain train --resume runs/flat          # continue from the last checkpoint
    skillchain summarize runs/flat               # the table of returns per episode window
    skillchain train ... --workers 2             # agents in blocks on Ray workers (distributed.py)
    skillchain sweep grid.toml --out sweeps/x    # a grid of runs on Ray, its table (study/sweep)

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

import dataclasses
import json
import os
import sys
from pathlib import Path

from skillchain_torch.trainers.config.arguments import CONFIG_OPTIONS, build_parser
from skillchain_torch.trainers.config.config import UNREAD_FIELDS, TrainConfig
from skillchain_torch.trainers.config.fields import MLP_TOP_FIELDS
from skillchain_torch.trainers.config.registry import AGENTS
from skillchain_torch.trainers.outputs.out_dir import (
    _check_out,
    _fail,
    _prepare_out,
    _remove_created,
    _remove_outputs,
)
from skillchain_torch.trainers.outputs.run_outputs import source_commit, train_and_write

__all__ = ["main", "build_parser"]

def _attach_values(argv: list[str], flags: tuple[str, ...] = ("--obs-bounds",)) -> list[str]:
    """``--obs-bounds -2.4:2.4,...`` as ``--obs-bounds=-2.4:2.4,...``: argparse takes a value
    that starts with ``-`` for a flag, and the bounds' error message writes them this way."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] in flags and i + 1 < len(argv) and argv[i + 1].startswith("-") \
                and ":" in argv[i + 1]:
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
            continue
        out.append(argv[i])
        i += 1
    return out


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(_attach_values(list(sys.argv[1:] if argv is None else argv)))
    command = parser.commands[args.command]  # its errors are one line (arguments.Parser)
    if args.command == "summarize":
        from skillchain_torch.trainers.study.summary import summarize_dir

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
    if args.command == "eval":
        return _eval(command, args)
    if args.command == "plot":
        from skillchain_torch.trainers.study.compare import run_plot

        return run_plot(command, args)
    return _train(command, args)


def _eval(parser, args) -> int:
    from skillchain_torch.trainers.study.evaluate import evaluate, load_run, render_episodes

    if not 0.0 <= args.epsilon <= 1.0:
        parser.error(f"--epsilon must be in [0, 1], got {args.epsilon}")
    try:
        run = load_run(args.dir)
        if not 0 <= args.agent_index < run.config.runs:
            parser.error(f"--agent-index must be in [0, {run.config.runs - 1}], got "
                         f"{args.agent_index}")  # fmt: skip
        result = evaluate(run, episodes=args.episodes, epsilon=args.epsilon,
                          max_steps=args.max_steps, seed=args.seed, quiet=args.quiet)
        print(f"{args.dir}: {run.config.agent} agents from {run.checkpoint.name}")
        print(result.table())
        if args.render is not None:
            path = render_episodes(run, args.render, agent_index=args.agent_index,
                                   episodes=args.render_episodes, epsilon=args.epsilon,
                                   max_steps=args.max_steps, seed=args.seed)
            print(f"animation: {path}")
    except (ValueError, TypeError) as err:
        parser.error(_one_line(err))
    return 0


def _reproduce(parser, args) -> int:
    from skillchain_torch.trainers.study.reproduce import reproduce_paper

    try:
        if args.report_only:
            from skillchain_torch.trainers.study.paper_report import write_report

            path = write_report(args.out, quiet=args.quiet)
        else:
            path = reproduce_paper(args.out, runs=args.runs, episodes=args.episodes,
                                   hard_runs=args.hard_runs, hard_episodes=args.hard_episodes,
                                   seed=args.seed, jobs=args.jobs, instances=args.instances,
                                   quiet=args.quiet, preset=args.preset,
                                   **({"slots": args.slots} if args.slots else {}))  # fmt: skip
    except (ValueError, RuntimeError) as err:
        parser.error(str(err))
    except KeyboardInterrupt:
        print("\ninterrupted; continue with the same command", file=sys.stderr)
        return 130
    print(f"report: {path}")
    return 0


def _sweep(parser, args) -> int:
    from skillchain_torch.trainers.distributed.ray_runs import require_ray
    from skillchain_torch.trainers.study.sweep import run_sweep

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
    from skillchain_torch.trainers.study.verify import verify_run

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
    for name in ("keep_negatives", "store_failures", "constrain_nearest",
                 "intra_option_primitives", "option_interruption"):
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
    learner = [n for n in MLP_TOP_FIELDS if n in given]
    if learner and given.get("top_head") != "mlp":
        parser.error(", ".join(map(_flag, learner)) + " set the learner of --top-head mlp, "
                     "and the top level here is fourier (closed-form Sarsa): add --top-head mlp "
                     "or leave them out")  # fmt: skip
    if getattr(args, "config", None) is not None:  # the file's values under the flags given
        saved = {k: v for k, v in _read_config_file(parser, args.config).items()
                 if v is not None}  # (None: left to the defaults, as a flag not given)
        if "env" in given or "map" in given:  # a flag's environment replaces the file's
            for name in ("env", "map", "obs_bounds", "obs_dim", "num_actions"):
                saved.pop(name, None)
        given = {**saved, **given}
    if "env" in given and "map" in given:
        parser.error("--env and --map choose the environment twice: give one (--map is Pinball's)")
    if "obs_bounds" in given and "env" not in given:
        parser.error("--obs-bounds applies to --env only (Pinball's observation is bounded)")
    try:
        config = TrainConfig(**given)
        if config.env is not None:  # its sizes (and so the default order) from its specs
            from skillchain_torch.trainers.loop.population import with_env_sizes

            config = with_env_sizes(config)
        return config.validate().resolved()
    except ValueError as err:
        parser.error(_flag_message(err, given))


def _read_config_file(parser, path: Path) -> dict:
    """The fields of ``--config FILE``: a run's ``config.json`` (read as ``--resume`` reads it)
    or a TOML table of :class:`TrainConfig` fields; one line naming the file otherwise."""
    if path.suffix == ".json":
        try:
            return TrainConfig.load_json(path).to_dict()
        except ValueError as err:
            parser.error(f"--config {err}")
    if path.suffix != ".toml":
        parser.error(f"--config {path}: expected a .json (a run's config.json) or .toml file")
    import tomllib

    try:
        data = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as err:
        parser.error(f"--config {path}: cannot read it ({_one_line(err)})")
    names = {f.name for f in dataclasses.fields(TrainConfig)}
    unknown = sorted(set(data) - names)
    if unknown:
        parser.error(f"--config {path}: unknown field {unknown[0]!r} (TrainConfig's fields are "
                     f"the flags of skillchain train, with _ for -)")  # fmt: skip
    return data


def _one_line(message) -> str:
    """``message`` on one line (torch's and numpy's errors span several)."""
    return " ".join(str(message).split())


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
    from skillchain_torch.trainers.loop.population import PopulationTrainer
    from skillchain_torch.trainers.outputs.checkpoint import (
        extend_run,
        latest_checkpoint,
        resume_checkpoint,
    )

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
        given = [_flag(n) for n in CONFIG_OPTIONS if getattr(args, n) is not None
                 and n != "episodes"]  # (--episodes N extends the run)
        given += ["--out"] * (args.out is not None) + ["--overwrite"] * args.overwrite
        given += ["--config"] * (args.config is not None)
        if given:
            parser.error(f"--resume continues with the saved config, writing into {out}; do "
                         f"not pass " + ", ".join(given) + " (only --episodes, to extend it)")
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
        extend = args.episodes is not None and args.episodes != config.episodes
        if extend and args.episodes < config.episodes:
            parser.error(f"--episodes {args.episodes} is fewer than the {config.episodes} of "
                         f"{out}: a run can be extended, not shortened")  # fmt: skip
        if sharded or (out / "sharding.json").is_file():
            if extend:  # every block from its newest checkpoint before an agent finished
                from skillchain_torch.trainers.distributed.blocks import ShardedRun, extend_blocks

                config = dataclasses.replace(config, episodes=args.episodes)
                try:
                    extend_blocks(ShardedRun.load(out, config), native=native)
                except ValueError as err:
                    parser.error(_one_line(err))
                config.save_json(out / "config.json")
            return _train_sharded(parser, args, config, out, native, resume=True)
        checkpoint = latest_checkpoint(out)
        if checkpoint is None:
            parser.error(f"--resume {out}: no checkpoint under {out / 'checkpoints'}")
        try:
            if extend:  # from the newest checkpoint before any agent finished
                config = dataclasses.replace(config, episodes=args.episodes)
                trainer = PopulationTrainer(config, out_dir=out, num_threads=args.threads,
                                            native=native)  # fmt: skip
                checkpoint = extend_run(out, trainer)
                config.save_json(out / "config.json")
            else:
                trainer = PopulationTrainer(config, out_dir=out, num_threads=args.threads,
                                            native=native)  # fmt: skip
                checkpoint = resume_checkpoint(out, trainer)  # damaged newer: the one before
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
        from skillchain_torch.trainers.distributed.ray_runs import require_ray

        try:
            require_ray("--workers" if sharded else f"--resume {args.resume} (a sharded run)")
        except ImportError as err:
            parser.error(str(err))
    return sharded


def _train_sharded(parser, args, config, out: Path, native, resume: bool) -> int:
    """Train ``config``'s agents in blocks on Ray workers and merge them into ``out``."""
    import time

    from skillchain_torch.trainers.distributed.blocks import (
        ShardedRun,
        plan_blocks,
        record_driver_wall,
    )
    from skillchain_torch.trainers.distributed.ray_runs import run_sharded

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
        return train_and_write(trainer, out, quiet)
    except FloatingPointError as err:  # a learner diverged; the trainer saved what it had
        if parser is None:
            raise
        _fail(parser, _one_line(err))
    except (OSError, RuntimeError) as err:
        reason = _write_error(err)
        if reason is None or parser is None:
            raise
    from skillchain_torch.trainers.outputs.checkpoint import latest_checkpoint

    if latest_checkpoint(out) is not None:
        hint = f"; once it can be written, continue with: skillchain train --resume {out}"
    else:  # nothing to resume: leave nothing that would refuse the same command again
        _remove_created(created)
        if created is None:
            _remove_outputs(out)
        hint = "; nothing to resume (no checkpoint was written), run the same command again"
    _fail(parser, f"cannot write the run's outputs in {out}: {reason}{hint}")


if __name__ == "__main__":
    sys.exit(main())
