"""Options for a population of agents: slots, policies, initiation sets, termination events.

The pieces (paper sections 2, 4 and 5.1), each batched over ``[P, K]`` (agents x option slots):

- :class:`OptionStatus`: EMPTY / GESTATING / LEARNING / LEARNED per slot.
- :class:`FourierOptionQHead` (the paper's linear learner) and :class:`MLPOptionQHead` (a
  ``torch.func``-stacked neural drop-in), both :class:`OptionQHead`.
- :class:`InitiationClassifier`: logistic regression over polynomial features per slot; its
  fitting maths in :func:`logistic_sweeps`, where examples go in its stores in
  :func:`store_places`. :class:`MLPInitiationClassifier`: the same sets with an MLP per slot.
- Termination predicates: :class:`GoalEvent`, :class:`RegionEvent`, :class:`InitiationSetEvent`,
  :class:`LambdaEvent`.
- :class:`OptionBank`: bundles the above with per-slot metadata; save / load / select agents.
  A part of the user's own class loads once registered (:func:`register_q_head`,
  :func:`register_classifier`).

The intra-option Q-learning update lives in
:class:`skillchain_torch.objectives.IntraOptionQLearning`.
"""

from skillchain_torch.options.bank import FORMAT_VERSION, OptionBank
from skillchain_torch.options.examples import reservoir_uniform, store_places
from skillchain_torch.options.goals import TransitionGoal, env_goal, goal_event
from skillchain_torch.options.initiation import InitiationClassifier
from skillchain_torch.options.io import register_classifier, register_q_head
from skillchain_torch.options.logistic import logistic_sweeps
from skillchain_torch.options.mlp_initiation import MLPInitiationClassifier
from skillchain_torch.options.mlp_q_head import MLPOptionQHead
from skillchain_torch.options.q_head import FourierOptionQHead, OptionQHead
from skillchain_torch.options.status import OptionStatus, slot_mask
from skillchain_torch.options.termination import (
    GoalEvent,
    InitiationSetEvent,
    LambdaEvent,
    RegionEvent,
    TerminationPredicate,
)

__all__ = [
    "FORMAT_VERSION",
    "FourierOptionQHead",
    "GoalEvent",
    "TransitionGoal",
    "env_goal",
    "goal_event",
    "InitiationClassifier",
    "InitiationSetEvent",
    "LambdaEvent",
    "MLPInitiationClassifier",
    "MLPOptionQHead",
    "OptionBank",
    "OptionQHead",
    "OptionStatus",
    "RegionEvent",
    "TerminationPredicate",
    "logistic_sweeps",
    "register_classifier",
    "register_q_head",
    "reservoir_uniform",
    "slot_mask",
    "store_places",
]
