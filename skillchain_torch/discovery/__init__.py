"""Skill discovery by skill chaining (Konidaris & Barto 2009, sections 4 and 5.1).

Each rule is a named piece with the paper's value as its default:

- :mod:`.events`: the target-event list (base events such as the goal, learned initiation
  sets), the branching limit (``MAX_BRANCHING = 3``) and what "triggering" an event means.
- :mod:`.creation`: create an option when a listed event fires, unless the start state is
  covered by an option already targeting it.
- :mod:`.gestation`: ``GESTATION_EPISODES = 10`` of off-policy learning, then ``Q(s, o)``
  initialised to the largest sampled value.
- :mod:`.executions`: positive and negative initiation-set examples from executions, and the
  dropped updates of failed ones.
- :mod:`.convergence`: learned when the classifier moved less than 0.15 in two episodes.
- :mod:`.overlap`: an option's set stays out of its parent's and its older siblings'.
- :mod:`.readings`: the readings of what the paper leaves open about initiation sets
  (gestation positives, the set when gestation ends, when the distance constraint applies).
- :class:`SkillChaining`: the state of a population's discovery, applying all of the above.
"""

from skillchain_torch.discovery.convergence import (
    CONVERGENCE_EPISODES,
    CONVERGENCE_THRESHOLD,
    ConvergenceTest,
)
from skillchain_torch.discovery.creation import choose_creation, covered_start
from skillchain_torch.discovery.events import (
    MAX_BRANCHING,
    entered,
    evaluate_base_events,
    event_list,
    target_indicator,
    targeting,
)
from skillchain_torch.discovery.executions import ExecutionTrace, execution_outcome
from skillchain_torch.discovery.gestation import (
    GESTATION_EPISODES,
    RecentStates,
    gestation_over,
    initialise_option_values,
)
from skillchain_torch.discovery.overlap import exclude_overlap, overlap_exclusion
from skillchain_torch.discovery.readings import (
    DEFAULT_READING,
    FIRST_READING,
    InitiationReading,
)
from skillchain_torch.discovery.skill_chaining import DiscoveryEvent, SkillChaining

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
