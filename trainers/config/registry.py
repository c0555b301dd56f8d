"""The agent registry: ``--agent NAME`` -> a class built as ``cls(config, device=...)``.

Adding an agent type is one entry here; the CLI's ``--agent`` choices and
:class:`TrainConfig` validation read this dict. Entries are ``"module:Class"`` paths (a dotted
module path is absolute, a bare name is a module of this package), imported on first use (so
listing the choices does not import torch).

An agent follows the episode protocol of
:class:`~skillchain_torch.agents.flat_sarsa.FlatSarsaAgent`: ``begin``,
``observe``, ``observe_ends``, ``compact``, ``actions``, ``index``, ``flush``, ``state_dict`` and
``load_state_dict``.

Example:
    >>> sorted(AGENTS)
    ['flat', 'given-options', 'skill-chaining']
    >>> agent_class("flat").__name__
    'FlatSarsaAgent'
"""

from __future__ import annotations

import importlib
import inspect

__all__ = ["AGENTS", "agent_class", "make_agent"]

AGENTS: dict[str, str] = {
    "flat": "skillchain_torch.agents.flat_sarsa:FlatSarsaAgent",
    "given-options": "skillchain_torch.agents.given_options:GivenOptionsAgent",
    "skill-chaining": "skillchain_torch.agents.skill_chaining_run:SkillChainingRunAgent",
}


def agent_class(name: str) -> type:
    """The class registered as ``name``; ``ValueError`` listing the known agents otherwise."""
    try:
        module, cls = AGENTS[name].split(":")
    except KeyError:
        raise ValueError(f"unknown agent {name!r}; known agents: {', '.join(AGENTS)}") from None
    return getattr(importlib.import_module(module if "." in module else f"{__package__}.{module}"),
                   cls)


def make_agent(config, device=None, native: bool | None = None):
    """Build the registered agent named ``config.agent``.

    ``native`` reaches agents whose constructor takes it (the flat agent's compiled kernels);
    ``None`` keeps each agent's default.
    """
    cls = agent_class(config.agent)
    if native is not None and "native" in inspect.signature(cls).parameters:
        return cls(config, device=device, native=native)
    return cls(config, device=device)
