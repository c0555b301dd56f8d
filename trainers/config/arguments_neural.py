"""``skillchain train``'s flags for the skill-chaining agent's pieces and for what neural pieces
need: the pieces by name, the MLP top level's learner, and an annealed exploration.

Example:
    >>> import argparse
    >>> parser = argparse.ArgumentParser()
    >>> add_neural_arguments(parser)
    >>> args = parser.parse_args(["--top-head", "mlp", "--epsilon-init", "1", "--annealing-steps",
    ...                           "10000"])
    >>> args.top_head, args.epsilon_init, args.annealing_steps, args.top_lr
    ('mlp', 1.0, 10000, None)
"""

from __future__ import annotations

import argparse

from skillchain_torch.presets import TOP_LEARNER

__all__ = ["NEURAL_OPTIONS", "add_neural_arguments"]

# TrainConfig fields these flags set (None: not given, the config's default).
NEURAL_OPTIONS = ("top_head", "option_head", "initiation", "top_lr", "top_target_update",
                  "top_bootstrap", "epsilon_init", "annealing_steps")  # fmt: skip


def add_neural_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the pieces' flags (``--top-head``, ``--option-head``, ``--initiation``), the MLP top
    level's learner (``--top-lr``, ``--top-target-update``, ``--top-bootstrap``) and the
    exploration schedule (``--epsilon-init``, ``--annealing-steps``) to ``parser``."""
    for flag, paper in (("--top-head", "fourier"), ("--option-head", "fourier"),
                        ("--initiation", "logistic")):  # fmt: skip
        parser.add_argument(flag, default=None, metavar="NAME",
                            help=f"skill chaining's piece: {paper} (the paper's, default) or mlp "
                            "(neural; skillchain_torch.agents.pieces)")  # fmt: skip
    parser.add_argument("--top-lr", type=float, default=None, metavar="LR",
                        help=f"--top-head mlp: Adam's step size (default {TOP_LEARNER['lr']:g})")
    parser.add_argument("--top-target-update", type=int, default=None, metavar="N",
                        help="--top-head mlp: optimizer steps between target-network copies "
                        f"(default {TOP_LEARNER['target_update']})")  # fmt: skip
    parser.add_argument("--top-bootstrap", choices=("max", "sarsa"), default=None,
                        help="--top-head mlp: TD target over the next decisions, max (DQN's, "
                        "default) or the one taken (sarsa, the paper's rule)")  # fmt: skip
    parser.add_argument("--epsilon-init", type=float, default=None, metavar="EPS",
                        help="explore at EPS at the first step (the top level, for skill "
                        "chaining and given options), annealed "
                        "linearly to --epsilon over --annealing-steps agent steps (default: "
                        "--epsilon throughout, as the paper; neural heads need it)")  # fmt: skip
    parser.add_argument("--annealing-steps", type=int, default=None, metavar="N",
                        help="with --epsilon-init: agent steps from it to --epsilon")
