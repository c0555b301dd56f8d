"""Named pieces of a skill-chaining agent: which top-level head, option head and initiation set.

Three registries, one per piece a researcher swaps, each mapping a name to a builder:

=================  =============================================  ==============================
registry           ``"fourier"`` / ``"logistic"`` (the paper's)   ``"mlp"`` (neural, issue 31)
=================  =============================================  ==============================
:data:`TOP_HEADS`  LinearQHead on a Fourier basis, SMDP Sarsa     MLPQHead on the observation,
                   in closed form                                 Huber loss, target net, replay
:data:`OPTION_     FourierOptionQHead, Q-learning at alpha_o      MLPOptionQHead (scaled errors),
HEADS`                                                            OptionReplay, target net
:data:`INITIA-     InitiationClassifier (logistic, quadratic)     MLPInitiationClassifier
TIONS`
=================  =============================================  ==============================

``SkillChainingAgent.build(..., top_head="mlp", option_head="mlp", initiation="mlp")`` and
``skillchain train --top-head mlp --option-head mlp --initiation mlp`` read them. Add your own
with :func:`register_piece`; a saved option bank reloads its parts through the option registry
(:func:`~skillchain_torch.options.register_q_head`, :func:`~skillchain_torch.options.
register_classifier`).

Example:
    >>> sorted(TOP_HEADS), sorted(OPTION_HEADS), sorted(INITIATIONS)
    (['fourier', 'mlp'], ['fourier', 'mlp'], ['logistic', 'mlp'])
    >>> from skillchain_torch.agents import SkillChainingAgent
    >>> agent = SkillChainingAgent.build(2, preset="paper", top_head="mlp", option_head="mlp",
    ...                                  initiation="mlp", order=1)
    >>> type(agent.q_head).__name__, type(agent.bank.q_head).__name__, agent.native
    ('MLPQHead', 'MLPOptionQHead', False)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from torch import nn

from skillchain_torch.modules import MLPQHead
from skillchain_torch.objectives import OptionReplay, ReplayTD, SMDPSarsaLoss
from skillchain_torch.options import MLPInitiationClassifier, MLPOptionQHead, OptionBank
from skillchain_torch.presets import TOP_LEARNER

__all__ = ["INITIATIONS", "OPTION_HEADS", "TOP_HEADS", "TOP_LEARNER", "assemble_bank",
           "register_piece", "top_level_arguments"]

# The neural defaults: sized for observations of a few dims and returns of order 10^4.
VALUE_SCALE = 1000.0  # Q / 1000: outputs and TD errors of order 10 (Pinball's goal: 10^4)


def _replay_seed(seed, offset: int = 0):
    """A learner's sampling seed: agent p samples with its own seed (``seed + p`` for an int,
    ``seed[p]`` for per-agent seeds), plus ``offset``."""
    return seed.reshape(-1) + offset if isinstance(seed, torch.Tensor) else int(seed) + offset


def _mlp_top(population: int, obs_dim: int, num_decisions: int, gamma: float, seed: int,
             device, lr: float = TOP_LEARNER["lr"],
             target_update: int = TOP_LEARNER["target_update"],
             bootstrap: str = TOP_LEARNER["bootstrap"]) -> dict[str, Any]:  # fmt: skip
    """An MLP top level learning by SMDP TD on replayed minibatches: ``bootstrap`` ``"max"``
    (Q-learning over the available decisions, DQN's target) or ``"sarsa"`` (the decision taken
    next, the paper's rule), Adam at ``lr``, the target copied every ``target_update`` updates."""
    head = MLPQHead(obs_dim, num_decisions, population, hidden=64, layers=2,
                    value_scale=VALUE_SCALE, seed=seed, device=device)  # fmt: skip
    loss = SMDPSarsaLoss(head, gamma, loss_function="smooth_l1", value_scale=VALUE_SCALE,
                         delay_value=True, bootstrap=bootstrap)  # fmt: skip
    optimizer = torch.optim.Adam(head.parameters(), lr=lr)
    learner = ReplayTD(loss, optimizer, capacity=50_000, batch_size=32,
                       target_update=target_update, train_every=4,
                       seed=_replay_seed(seed))  # fmt: skip
    return {"q_head": head, "features": nn.Identity(), "top_learner": learner}


def _mlp_option_head(population: int, slots: int, num_actions: int, obs_dim: int, seed: int,
                     device, **_: Any):  # fmt: skip
    head = MLPOptionQHead(population, slots, hidden=32, layers=2, num_actions=num_actions,
                          lr=0.01, q_scale=VALUE_SCALE, seed=seed, device=device,
                          obs_dim=obs_dim)  # fmt: skip
    head.replay = OptionReplay(capacity=50_000, batch_size=32, train_every=4,
                               target_update=250, seed=_replay_seed(seed, 1))  # fmt: skip
    return head


def _mlp_initiation(classifier) -> MLPInitiationClassifier:
    """The logistic classifier's store and rule settings, with an MLP per slot."""
    kept = {k: v for k, v in classifier.config.items() if k not in ("degree", "lr", "sweeps")}
    return MLPInitiationClassifier(hidden=16, layers=2, lr=0.02, sweeps=30,
                                   seed=classifier.seeds.clone(),
                                   device=classifier.seeds.device, **kept)  # fmt: skip


# name -> builder. A top-level builder returns the agent's keyword arguments ({}: the paper's
# LinearQHead on a FourierBasis, built by the agent); an option-head builder returns an
# OptionQHead (None: keep the bank's Fourier heads); an initiation builder maps the bank's
# logistic classifier to the set to use (None: keep it).
TOP_HEADS: dict[str, Callable | None] = {"fourier": None, "mlp": _mlp_top}
OPTION_HEADS: dict[str, Callable | None] = {"fourier": None, "mlp": _mlp_option_head}
INITIATIONS: dict[str, Callable | None] = {"logistic": None, "mlp": _mlp_initiation}
_REGISTRIES = {"top_head": TOP_HEADS, "option_head": OPTION_HEADS, "initiation": INITIATIONS}


def register_piece(kind: str, name: str, build: Callable) -> Callable:
    """Make ``name`` a choice for ``kind`` (``"top_head"``, ``"option_head"``,
    ``"initiation"``), built by ``build`` (the signatures of this module's ``_mlp_*``)."""
    if kind not in _REGISTRIES:
        raise ValueError(f"kind must be one of {', '.join(_REGISTRIES)}, got {kind!r}")
    _REGISTRIES[kind][name] = build
    return build


def _lookup(kind: str, name: str) -> Callable | None:
    registry = _REGISTRIES[kind]
    if name not in registry:
        flag = "--" + kind.replace("_", "-")
        raise ValueError(f"{flag} must be one of {', '.join(sorted(registry))}, got {name!r}")
    return registry[name]


def assemble_bank(bank: OptionBank, option_head: str = "fourier",
                  initiation: str = "logistic", seed: int = 0) -> OptionBank:  # fmt: skip
    """``bank`` (the paper's, from :meth:`OptionBank.build`) with the named parts swapped in."""
    build_head, build_set = _lookup("option_head", option_head), _lookup("initiation", initiation)
    if build_head is None and build_set is None:
        return bank
    device = bank.status.device
    q_head = bank.q_head if build_head is None else build_head(
        bank.population, bank.slots, num_actions=bank.num_actions, obs_dim=bank.obs_dim,
        seed=seed, device=device)  # fmt: skip
    classifier = bank.classifier if build_set is None else build_set(bank.classifier)
    return OptionBank(bank.population, bank.slots, q_head, classifier)


def top_level_arguments(top_head: str, population: int, obs_dim: int, num_decisions: int,
                        gamma: float = 1.0, seed=0, device=None,
                        learner: dict[str, Any] | None = None) -> dict[str, Any]:  # fmt: skip
    """The agent's keyword arguments for the named top level (``{}`` for the paper's);
    ``learner``: keyword arguments of its builder's learner (the built-in ``"mlp"`` reads
    ``lr``, ``target_update`` and ``bootstrap``; :data:`TOP_LEARNER` by default)."""
    build = _lookup("top_head", top_head)
    if build is None:
        if learner:
            raise ValueError(f"top_learner {sorted(learner)} is for a top level with a learner of "
                             f"its own; {top_head!r} learns by closed-form Sarsa")  # fmt: skip
        return {}
    return build(population, obs_dim, num_decisions, gamma, seed, device, **(learner or {}))
