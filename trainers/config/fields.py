"""Which fields of a :class:`~.config.TrainConfig` a saved run reads, compares or labels.

Kept apart from the config itself: these are the rules for comparing a saved run with a new
config (resume, verify), not the run's values.
"""

from __future__ import annotations

__all__ = ["LABEL_FIELDS", "LEGACY_FIELDS", "MLP_TOP_FIELDS", "RESUME_FIELDS", "UNREAD_FIELDS"]

# Fields added after runs were published, with the behaviour every run before them had: a
# saved config without one of them ran with this value (whatever today's default is).
LEGACY_FIELDS = {"preset": "default", "max_option_steps": 250, "failure_bootstrap": "decision",
                 "keep_negatives": False,
                 "policy_start": "zero", "value_start": "max-sample", "value_bonus": 0.0,
                 "option_alpha": 0.0005,
                 "completion_reward": 10_000.0, "gestation": 10, "convergence_threshold": 0.15,
                 "intra_option_primitives": False, "intra_option_target": "decisions",
                 "store_failures": False, "constrain_nearest": False,
                 "option_interruption": False, "end_outside_set": "off",
                 "top_head": "fourier", "option_head": "fourier", "initiation": "logistic",
                 "max_branching": 3, "top_lr": 1e-3, "top_target_update": 250,
                 "top_bootstrap": "sarsa", "epsilon_init": None, "annealing_steps": 0,
                 "subgoals": "chained", "goal": None}

# Fields that may differ between a checkpoint and the trainer that loads it: they change how
# the run is written down or where it computes, not the numbers it produces.
RESUME_FIELDS = ("checkpoint_every", "checkpoint_minutes", "keep_checkpoints", "device")
# Where the values came from: a label only (the values themselves are fields), so two configs
# with the same values are the same run whichever preset they started from.
LABEL_FIELDS = ("preset",)

# Fields an agent kind never reads: a saved run of that kind does not differ from a config that
# changes them (so a flat run stays valid when a skill-chaining default changes).
_DISCOVERY_FIELDS = ("slots", "initiation_bias", "initiation_centered", "gestation_positives",
                     "initiation_start", "initiation_constrain", "one_class_fits",
                     "keep_negatives", "store_failures", "constrain_nearest", "policy_start",
                     "value_start",
                     "value_bonus", "option_alpha", "gestation", "convergence_threshold",
                     "max_branching", "subgoals")
# The "mlp" top level's learner: a run whose top level is the built-in Fourier head never reads
# them (so a saved Fourier run stays valid when the paper preset's MLP learner values change).
MLP_TOP_FIELDS = ("top_lr", "top_target_update", "top_bootstrap")
# (epsilon_init and annealing_steps are read by every kind: the trainer anneals any agent's
# exploration through its set_epsilon.)
_PIECES = ("top_head", "option_head", "initiation", *MLP_TOP_FIELDS)
UNREAD_FIELDS = {
    "flat": _DISCOVERY_FIELDS + _PIECES + ("options", "options_agent", "failure_bootstrap", "goal",
                                           "max_option_steps",
                                           "completion_reward", "intra_option_primitives",
                                           "intra_option_target",
                                           "option_interruption", "end_outside_set"),
    "given-options": _DISCOVERY_FIELDS + _PIECES,
    "skill-chaining": ("options", "options_agent"),
}
