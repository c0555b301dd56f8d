"""The ``skillchain`` command line's arguments: every command's parser and argument types.

:func:`build_parser` is what ``skillchain`` parses with (``trainers/cli.py`` runs the
commands); ``CONFIG_OPTIONS`` are the options that define a run (:class:`TrainConfig`'s fields;
with ``--resume`` the saved config is used instead).

Example:
    >>> args = build_parser().parse_args(["train", "--agent", "flat", "--runs", "4"])
    >>> args.command, args.agent, args.runs
    ('train', 'flat', 4)
"""

from __future__ import annotations

import argparse
from pathlib import Path

from skillchain_torch.presets import PRESET_NAMES
from skillchain_torch.trainers.config.arguments_discovery import add_discovery_arguments
from skillchain_torch.trainers.config.arguments_neural import NEURAL_OPTIONS, add_neural_arguments
from skillchain_torch.trainers.config.registry import AGENTS

__all__ = ["build_parser", "CONFIG_OPTIONS"]

# Options that define the run; with --resume the saved config is used instead.
CONFIG_OPTIONS = (
    "agent", "preset", "map", "env", "obs_bounds", "runs", "episodes", "seed", "alpha", "epsilon",
    "gamma", "order", "scale_step_size", "max_episode_steps", "checkpoint_every",
    "checkpoint_minutes", "keep_checkpoints", "options",
    "options_agent", "slots", "initiation_bias", "initiation_centered", "gestation_positives",
    "initiation_start", "initiation_constrain", "one_class_fits", "failure_bootstrap",
    "keep_negatives", "store_failures", "constrain_nearest", "intra_option_primitives",
    "intra_option_target", "option_interruption", "end_outside_set", "policy_start",
    "value_start", "value_bonus", "option_alpha", "completion_reward", "gestation",
    "max_option_steps", "convergence_threshold", "max_branching", "subgoals", "goal",
    *NEURAL_OPTIONS,
)  # fmt: skip


class Parser(argparse.ArgumentParser):
    """argparse, with an error as its one line and no usage above it: ``skillchain train``
    has ~60 flags, and its usage (35 lines) buried the line that matters (``--help`` shows it)."""

    def error(self, message: str):
        if " " not in self.prog:  # bare ``skillchain``: its short usage lists the commands
            super().error(message)
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
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
    train.add_argument("--preset", choices=PRESET_NAMES, default=None,
                       help="the values every flag below not given takes: the library's "
                       "(default) or the paper's section 5.1 (paper); explicit flags win")
    train.add_argument(
        "--map", default=None, help="Pinball map name (default: pinball_simple_single)"
    )
    train.add_argument(
        "--env", default=None, metavar="gymnasium:ID",
        help="train on a Gymnasium env instead of Pinball: MountainCar-v0 (or "
        "gymnasium:MountainCar-v0), or gymnasium:MODULE:ID for an env your module registers "
        "(observation size, bounds and action count come from its specs; MountainCar steps "
        "as one batch, others through TorchRL's GymEnv)",
    )
    train.add_argument(
        "--goal", default=None, metavar="NAME",
        help="the goal event options are built towards: terminated (the env's own "
        "termination), terminated-positive (terminated with a positive last reward: "
        "LunarLander's landing, not its crash), or MODULE:FUNCTION of the transition's "
        "TensorDict (default: the env's, terminated on Pinball, MountainCar and Acrobot; "
        "CartPole has none and needs one for skill chaining)",
    )
    train.add_argument(
        "--obs-bounds", default=None, metavar="LOW:HIGH,...",
        help="the observation's bounds, one LOW:HIGH per dim, where the env's spec has none "
        "(Fourier features and initiation sets live in the unit box)",
    )
    add_neural_arguments(train)
    train.add_argument("--max-branching", type=int, default=None, help="options per target "
                       "event (paper and default: 3; 0: none, a flat baseline for any head)")
    train.add_argument("--runs", type=int, default=None, help="P, independent agents (default 1)")
    train.add_argument(
        "--episodes", type=int, default=None, help="E, episodes per agent (default 100)"
    )
    train.add_argument("--seed", type=int, default=None, help="agent p uses seed + p (default 0)")
    train.add_argument(
        "--alpha",
        type=float,
        default=None,
        help="step size (default: 0.001 on simple maps, 0.0005 on hard maps; with --env, "
        "0.001 * 625 / (order + 1) ** obs_dim, as far per update as on Pinball: 0.025 on "
        "MountainCar)",
    )
    train.add_argument("--epsilon", type=float, default=None, help="exploration (default 0.01)")
    train.add_argument("--gamma", type=float, default=None, help="discount (default 1)")
    train.add_argument(
        "--order",
        type=int,
        default=None,
        help="Fourier order (default: 4 on simple maps, 5 on hard maps; with --env, the "
        "highest up to 4 with (order + 1) ** obs_dim <= 10,000)",
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
    add_discovery_arguments(train)
    train.add_argument(
        "--checkpoint-every",
        type=int,
        default=None,
        help="checkpoint every N episodes of the slowest agent (default 25)",
    )
    train.add_argument(
        "--checkpoint-minutes",
        type=float,
        default=None,
        help="also checkpoint when M minutes of training passed since the last one, 0: never "
        "(default 30)",
    )
    train.add_argument(
        "--keep-checkpoints",
        type=int,
        default=None,
        metavar="N",
        help="keep only the newest N checkpoints (and the one a longer run would extend from); "
        "0: all (default 0; a neural run's checkpoints are 0.2-0.7 GB each)",
    )
    train.add_argument("--device", default=None, help="torch device (default cpu)")
    train.add_argument(
        "--threads", type=int, default=1, help="torch intra-op threads while training (default 1)"
    )
    train.add_argument("--out", type=Path, default=None, help="output directory")
    train.add_argument("--config", type=Path, default=None, metavar="FILE",
                       help="start from a run's config.json or a TOML file of TrainConfig "
                       "fields (agent = \"skill-chaining\", runs = 20, ...); flags given here "
                       "win over it")
    train.add_argument(
        "--resume",
        type=Path,
        metavar="DIR",
        default=None,
        help="continue the run in DIR from its last checkpoint; with --episodes N (more than "
        "it had), extend it: from its last checkpoint before an agent finished, the same run as "
        "one trained for N episodes from the start",
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
    reproduce.add_argument("--hard-runs", type=_positive, default=None,
                           help="runs per agent on the second instance (default: --runs)")
    reproduce.add_argument("--hard-episodes", type=_positive, default=None,
                           help="episodes per run on the second instance (default: --episodes)")
    reproduce.add_argument("--seed", type=int, default=1000,
                           help="agent p of every kind uses seed + p (default 1000)")
    reproduce.add_argument("--instances", nargs="+", choices=("simple", "hard"),
                           default=["simple", "hard"], help="which instances (default both)")
    reproduce.add_argument("--preset", choices=PRESET_NAMES, default="default",
                           help="the readings every run uses (default: the library's default; "
                           "'paper': every value the paper states)")
    reproduce.add_argument("--slots", type=_positive, default=None,
                           help="option slots per agent (default: the preset's)")
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
    evaluate = sub.add_parser(
        "eval",
        help="run a trained run's agents greedily and print their returns",
        description="Load RUN_DIR's agents from its last checkpoint, freeze them (no learning, "
        "no discovery) and run --episodes episodes each, greedy unless --epsilon, every episode "
        "cut at --max-steps; print each agent's mean return and the mean over agents with its "
        "95% interval. --render FILE.gif draws one agent's episodes.",
    )
    evaluate.add_argument("dir", type=Path, help="run directory (with checkpoints/)")
    evaluate.add_argument("--episodes", type=_positive, default=10,
                          help="episodes per agent (default 10)")
    evaluate.add_argument("--epsilon", type=float, default=0.0,
                          help="exploration while evaluating (default 0: greedy)")
    evaluate.add_argument("--max-steps", type=_positive, default=10_000,
                          help="steps per episode at most (default 10,000: a greedy agent can "
                          "circle forever)")
    evaluate.add_argument("--seed", type=int, default=None,
                          help="the evaluation's own streams (default: the run's seed + 1,000,000)")
    evaluate.add_argument("--render", type=Path, default=None, metavar="FILE.gif",
                          help="also draw one agent's episodes (Pinball, or a Gymnasium env "
                          "with rgb_array frames)")
    evaluate.add_argument("--agent-index", type=int, default=0,
                          help="the agent --render draws (default 0)")
    evaluate.add_argument("--render-episodes", type=_positive, default=1,
                          help="episodes --render draws (default 1)")
    evaluate.add_argument("--quiet", action="store_true", help="no progress bar")
    plot = sub.add_parser(
        "plot",
        help="draw several runs' learning curves in one figure and print their window table",
        description="Learning curves of finished runs with 95% bands in one figure (--out), "
        "and a table per episode window: each run's mean with its 95% t interval and each "
        "run minus the first with Welch's 95% interval (*: it excludes 0).",
    )
    from skillchain_torch.trainers.study.compare import add_plot_arguments

    add_plot_arguments(plot)
    group_train_flags(train)
    parser.commands = {"train": train, "summarize": summary, "reproduce": reproduce,
                       "verify": verify, "sweep": sweep, "eval": evaluate, "plot": plot}
    return parser


# ``skillchain train --help`` in groups, each flag's default in words (issue 54: 58 flags in one
# list, some without a default, some with jargon). Flags not named here stay in "options".
TRAIN_GROUPS = (
    ("run", "what to train and how long",
     ("agent", "preset", "config", "runs", "episodes", "seed", "max_episode_steps")),
    ("environment", "Pinball or a Gymnasium env, and its goal",
     ("map", "env", "obs_bounds", "goal")),
    ("agent", "the top level's learning (SMDP Sarsa over primitives and options)",
     ("alpha", "epsilon", "gamma", "order", "scale_step_size", "failure_bootstrap",
      "completion_reward", "intra_option_primitives", "intra_option_target",
      "option_interruption", "end_outside_set", "options", "options_agent")),
    ("discovery", "skill chaining: options, their initiation sets, gestation",
     ("slots", "max_branching", "subgoals", "gestation", "max_option_steps",
      "convergence_threshold",
      "option_alpha", "policy_start", "value_start", "value_bonus", "initiation_bias",
      "initiation_centered", "gestation_positives", "initiation_start",
      "initiation_constrain", "one_class_fits", "keep_negatives", "store_failures",
      "constrain_nearest")),
    ("neural", "neural pieces (skillchain_torch.agents.pieces)",
     ("top_head", "option_head", "initiation", "top_lr", "top_target_update",
      "top_bootstrap", "epsilon_init", "annealing_steps")),
    ("output", "where results go, resuming, and how the run computes",
     ("out", "resume", "overwrite", "checkpoint_every", "checkpoint_minutes", "keep_checkpoints",
      "quiet", "device",
      "threads",
      "torch_only", "workers", "block_size", "ray_address")),
)
_PLAIN_DEFAULTS = {"env": "none: Pinball", "obs_bounds": "the env's spec", "out": "none; "
                   "required unless --resume", "config": "none", "resume": "none",
                   "options": "none; required by --agent given-options",
                   "annealing_steps": "0: no annealing"}


def _words(value) -> str:
    if isinstance(value, bool):
        return "on" if value else "off"
    return str(value)


def group_train_flags(train: argparse.ArgumentParser) -> None:
    """Move ``train``'s flags into :data:`TRAIN_GROUPS` and give each a default in words."""
    from skillchain_torch.presets import DEFAULT, PAPER, PRESET_FIELDS

    actions = {a.dest: a for a in train._actions}
    for title, description, dests in TRAIN_GROUPS:
        group = train.add_argument_group(title, description)
        for dest in dests:
            action = actions[dest]
            for other in train._action_groups:
                if action in other._group_actions:
                    other._group_actions.remove(action)
            group._group_actions.append(action)
    for dest, action in actions.items():
        if action.help in (None, argparse.SUPPRESS):
            continue
        action.help = action.help.replace("reading: ", "how the paper is read where it is "
                                          "silent: ")  # fmt: skip
        if "default" in action.help:
            continue
        if dest in PRESET_FIELDS:
            ours, paper = getattr(DEFAULT, dest), getattr(PAPER, dest)
            action.help += (f" (default {_words(ours)}; --preset paper: {_words(paper)})"
                            if ours != paper else f" (default {_words(ours)})")
        elif dest in _PLAIN_DEFAULTS:
            action.help += f" (default: {_PLAIN_DEFAULTS[dest]})"
        elif action.default is False:
            action.help += " (default: off)"


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
