"""Learners' function approximators, batched over a population of agents."""

from skillchain_torch.modules.linear_q import LinearQHead
from skillchain_torch.modules.mlp_q import MLPQHead

__all__ = ["LinearQHead", "MLPQHead"]
