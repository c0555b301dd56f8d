"""Skill chaining (Konidaris & Barto, 2009) as TorchRL-style PyTorch components."""

__version__ = "0.1.0"
