"""Collectors: run environments with agents and yield TensorDict batches of transitions."""

from skillchain_torch.collectors.hierarchical import HierarchicalCollector

__all__ = ["HierarchicalCollector"]
