"""Skill discovery by skill chaining (Konidaris & Barto 2009, sections 4 and 5.1).

Each rule is a named piece with the paper's value as its default:

- :mod:`.skill_chaining`: the rules in the order the agent calls them, in one file: the
  target-event list and the branching limit (``MAX_BRANCHING = 3``), no overlap, the
  initiation-set examples of executions and the dropped updates of failed ones, creation
  unless the start state is covered, and :class:`SkillChaining`, which applies them.
- :mod:`.gestation`: ``GESTATION_EPISODES = 10`` of off-policy learning, then ``Q(s, o)``
  and the option's policy initialised (episode ends only).
- :mod:`.convergence`: learned when the classifier moved less than 0.15 in two episodes.
- :mod:`.readings`: the readings of what the paper leaves open about initiation sets
  (gestation positives, the set when gestation ends, when the distance constraint applies).
"""

from skillchain_torch.discovery.convergence import (
    CONVERGENCE_EPISODES,
    CONVERGENCE_THRESHOLD,
    ConvergenceTest,
)
from skillchain_torch.discovery.gestation import (
    GESTATION_EPISODES,
    gestation_over,
    initialise_option_values,
)
from skillchain_torch.discovery.readings import (
    DEFAULT_READING,
    FIRST_READING,
    InitiationReading,
)
from skillchain_torch.discovery.skill_chaining import (
    MAX_BRANCHING,
    DiscoveryEvent,
    ExecutionTrace,
    RecentStates,
    SkillChaining,
    choose_creation,
    covered_start,
    entered,
    evaluate_base_events,
    event_list,
    exclude_overlap,
    execution_outcome,
    overlap_exclusion,
    target_indicator,
    targeting,
)

__all__ = [
    "CONVERGENCE_EPISODES",
    "CONVERGENCE_THRESHOLD",
    "ConvergenceTest",
    "DEFAULT_READING",
    "FIRST_READING",
    "InitiationReading",
    "RecentStates",
    "DiscoveryEvent",
    "ExecutionTrace",
    "GESTATION_EPISODES",
    "MAX_BRANCHING",
    "SkillChaining",
    "choose_creation",
    "covered_start",
    "entered",
    "evaluate_base_events",
    "event_list",
    "exclude_overlap",
    "execution_outcome",
    "gestation_over",
    "initialise_option_values",
    "overlap_exclusion",
    "target_indicator",
    "targeting",
]
