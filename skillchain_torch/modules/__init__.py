"""Learners' function approximators, batched over a population of agents."""

from skillchain_torch.modules.linear_q import LinearQHead

__all__ = ["LinearQHead"]
