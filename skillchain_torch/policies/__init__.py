"""Decision rules over primitives and options."""

from skillchain_torch.policies.epsilon_greedy import (
    NUM_UNIFORMS,
    EpsilonGreedy,
    EpsilonGreedyModule,
    epsilon_greedy,
)
from skillchain_torch.policies.epsilon_schedule import LinearEpsilon, checked_epsilon

__all__ = ["NUM_UNIFORMS", "EpsilonGreedy", "EpsilonGreedyModule", "epsilon_greedy",
           "LinearEpsilon", "checked_epsilon"]
