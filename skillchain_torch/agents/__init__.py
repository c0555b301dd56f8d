"""Agents built from the library's pieces: the flat baseline, the hierarchical (options) agent
and helpers.

- :class:`FlatSarsaAgent`: the paper's baseline, Sarsa over primitive actions only.
- :class:`HierarchicalAgent`: SMDP Sarsa over primitives + options, intra-option Q-learning.
- :class:`SkillChainingAgent`: the same agent discovering its options by skill chaining.
- :func:`make_region_option`: a hand-built "reach the target region" option bank.
"""

from skillchain_torch.agents.flat_sarsa import FlatSarsaAgent
from skillchain_torch.agents.hierarchical import (
    MAX_OPTION_STEPS,
    NUM_PRIMITIVES,
    HierarchicalAgent,
    SkillChainingAgent,
)

__all__ = [
    "FlatSarsaAgent",
    "HierarchicalAgent",
    "MAX_OPTION_STEPS",
    "NUM_PRIMITIVES",
    "SkillChainingAgent",
    "make_region_option",
]


def __getattr__(name: str):
    # Imported on first use, so ``python -m skillchain_torch.agents.region_option`` does not
    # find its module already imported by the package.
    if name == "make_region_option":
        from skillchain_torch.agents.region_option import make_region_option

        return make_region_option
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
