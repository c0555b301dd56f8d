"""``skillchain train``'s flags for skill chaining's discovery (paper sections 4 and 5.1): the
option slots, how an initiation set starts and learns (the readings of the points section 5.1
leaves open), what the top level does around an option's execution, and how a new option's
policy and value start. Each flag left out takes the preset's value (``--preset``).

Example:
    >>> import argparse
    >>> parser = argparse.ArgumentParser()
    >>> add_discovery_arguments(parser)
    >>> args = parser.parse_args(["--gestation", "10", "--keep-negatives", "on"])
    >>> args.gestation, args.keep_negatives, args.policy_start
    (10, 'on', None)
"""

from __future__ import annotations

import argparse

from skillchain_torch.discovery.subgoals import SUBGOALS
from skillchain_torch.presets import DEFAULT, PAPER

__all__ = ["add_discovery_arguments"]


def add_discovery_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the discovery flags (``--slots`` to ``--completion-reward``) to ``parser``."""
    parser.add_argument(
        "--slots",
        type=int,
        default=None,
        help="option slots per agent for --agent skill-chaining (default: 48 on the hard "
        "Pinball instance, else 12)",
    )
    parser.add_argument(
        "--initiation-bias",
        type=float,
        default=None,
        help="intercept new initiation classifiers start from (default 0: true everywhere "
        "until the first fit, which starts from zero)",
    )
    parser.add_argument(
        "--initiation-centered",
        action="store_const",
        const=True,
        default=None,
        help="initiation classifiers on features of 2s-1 instead of s",
    )
    parser.add_argument(
        "--gestation-positives",
        type=int,
        default=None,
        metavar="N",
        help="reading: each time a gestating option's target fires, the last N states of the "
        "trajectory become positive examples, 0: none" + _presets("gestation_positives"),
    )
    parser.add_argument(
        "--initiation-start",
        choices=("everything", "biased", "fitted"),
        default=None,
        help="reading: the initiation set when gestation ends: true everywhere, true through "
        "--initiation-bias, or fitted on the gestation positives"
        + _presets("initiation_start"),
    )
    parser.add_argument(
        "--initiation-constrain",
        choices=("learned", "start"),
        default=None,
        help="reading: the 0.1 distance constraint once the set is learned, or from the end "
        "of gestation" + _presets("initiation_constrain"),
    )
    parser.add_argument(
        "--wait-for-both-classes",
        dest="one_class_fits",
        action="store_const",
        const=False,
        default=None,
        help="reading: fit an initiation set only once it holds both classes",
    )
    _on_off(parser, "--keep-negatives",
            "initiation-set stores never drop a failure to make room for a success's positives")
    _on_off(parser, "--store-failures", "a full initiation-set store never rejects a failure "
            "(it replaces a positive; off: the reservoir keeps it with chance 500 / (n + 1))")
    _on_off(parser, "--constrain-nearest", "a learned set leaves out states nearer to a stored "
            "failure than to any stored positive (off: the paper's 0.1 constraint alone)")
    _on_off(parser, "--intra-option-primitives",
            "the top level's primitive values also learn from the steps options take "
            "(one-step Q-learning; default off: only from the agent's own primitive decisions, "
            "as the paper's SMDP Sarsa)")
    parser.add_argument(
        "--intra-option-target",
        choices=("decisions", "primitives"),
        default=None,
        help="with --intra-option-primitives on: what those steps bootstrap on at s', the best "
        "decision (options included) or the best primitive" + _presets("intra_option_target"),
    )
    _on_off(parser, "--option-interruption",
            "an executing option stops where it is no longer the top level's greedy decision "
            "(default off: options run to their end, as the paper's)")
    parser.add_argument(
        "--end-outside-set",
        choices=("off", "learned", "always"),
        default=None,
        help="an executing option also ends where it leaves its own initiation set, as neither "
        "a success nor a failure: never (the paper's options run to their end), for options "
        "whose sets are learned, or always" + _presets("end_outside_set"),
    )
    parser.add_argument(
        "--failure-bootstrap",
        choices=("decision", "primitives"),
        default=None,
        help="what a timed-out option execution's SMDP target bootstraps on: the next "
        "decision (Sarsa) or the best primitive at s'" + _presets("failure_bootstrap"),
    )
    parser.add_argument(
        "--policy-start",
        choices=("zero", "top-level", "top-level-shifted"),
        default=None,
        help="how a new option's policy starts when it joins: zero weights updated off-policy "
        "in gestation, or the agent's own primitive values projected onto the option's basis "
        "(top-level-shifted: that copy plus completion reward minus the top level's value of "
        "the target, so the option's values and its own targets are on one scale)"
        + _presets("policy_start"),
    )
    parser.add_argument(
        "--value-start",
        choices=("max-sample", "agent"),
        default=None,
        help="how Q(s, o) starts when an option joins: the best value sampled when its target "
        "fired in gestation, everywhere, or the agent's own max_a Q(s, a) fitted in its basis "
        "plus --value-bonus" + _presets("value_start"),
    )
    parser.add_argument(
        "--value-bonus",
        type=float,
        default=None,
        help="added to Q(s, o) everywhere under --value-start agent (default 0)",
    )
    parser.add_argument(
        "--option-alpha",
        type=float,
        default=None,
        help="the options' Q-learning step size after they join, 0: an option keeps the policy "
        "it joins with" + _presets("option_alpha"),
    )
    parser.add_argument(
        "--gestation",
        type=int,
        default=None,
        help="episodes a new option gestates before it can be chosen" + _presets("gestation"),
    )
    parser.add_argument(
        "--max-option-steps",
        type=int,
        default=None,
        help="an option's execution gives up after this many steps, a failure"
        + _presets("max_option_steps"),
    )
    parser.add_argument(
        "--convergence-threshold",
        type=float,
        default=None,
        help="an initiation set is learned, and becomes a target event, when its weights moved "
        "less than this per episode twice in a row (default: the paper's 0.15)",
    )
    parser.add_argument(
        "--subgoals",
        choices=SUBGOALS,
        default=None,
        help="where new options aim: the sets of the options already there (chained, the "
        "paper's), or, as a control, the goal and one random disc per other slot (random: "
        "no chaining; skillchain_torch.discovery.subgoals) (default chained)",
    )
    parser.add_argument(
        "--completion-reward",
        type=float,
        default=None,
        help="added to an option's reward when its target fires (default 10000)",
    )


def _on_off(parser, flag: str, help: str) -> None:
    """A reading given as ``on`` / ``off`` (not given: the preset's; ``cli`` reads it as a bool)."""
    parser.add_argument(flag, choices=("on", "off"), default=None, help=help)


def _presets(field: str) -> str:
    """`` (default X; --preset paper: Y)`` for a flag's help, from the presets."""
    default, paper = getattr(DEFAULT, field), getattr(PAPER, field)
    return f" (default {default}; --preset paper: {paper})" if default != paper else ""
