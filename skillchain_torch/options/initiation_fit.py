"""Fitting, comparing and drawing an initiation set whose model is the user's own.

:class:`~skillchain_torch.options.InitiationClassifier` fits its logistic model in closed form
on ``weight``/``bias``. A subclass that overrides ``logit`` (``obs [P, *B, D] -> [P, *B, K]``)
has a model the closed form knows nothing of, so the classifier hands it here:

* :func:`gradient_fit`: the same fit (``sweeps`` full-batch steps of the mean log-loss over
  each slot's stored examples, classes weighted equally when ``balanced``) by autograd, on the
  model's ``requires_grad`` parameters, with the classifier's ``make_optimizer`` (SGD at
  ``lr`` unless overridden). With SGD on the logistic model this is the closed-form step.
* :func:`snapshot`: the model's logits at fixed probe points, ``[P, K, M]``: what the
  convergence test compares between episodes, since a general model has no per-slot weights.
* :func:`points_logit`: one slot's logit at many states (images), through the model's logit.

Example:
    >>> import torch
    >>> from torch import nn
    >>> from skillchain_torch.options import InitiationClassifier
    >>> class LinearOnObs(InitiationClassifier):      # logit = a . s + b, its own parameters
    ...     def __init__(self, **kw):
    ...         super().__init__(**kw)
    ...         self.a = nn.Parameter(torch.zeros(self.population, self.slots, 4,
    ...                                           dtype=torch.float64))
    ...     def logit(self, obs):
    ...         return torch.einsum("p...d,pkd->p...k", obs, self.a)
    >>> clf = LinearOnObs(population=1, slots=1, capacity=64, lr=1.0)
    >>> x = torch.rand(64, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    >>> _ = clf.add_examples(0, 0, x, x[:, 0] < 0.5)
    >>> _ = clf.fit()
    >>> bool(clf.a[0, 0, 0] < 0), clf.builtin_model()   # learned "left of x = 0.5"
    (True, False)
"""

from __future__ import annotations

import torch
from torch import Tensor
from torch.nn import functional

__all__ = ["PROBE_POINTS", "check_fittable", "gradient_fit", "points_logit", "probe", "snapshot"]

PROBE_POINTS = 64  # states where a model's logits are compared between episodes


def probe(clf, dim: int) -> Tensor:
    """``[M, dim]`` fixed points of the unit box (the observation's range), the same for every
    agent and episode: a generator of its own, seeded once, so no agent's stream is touched."""
    g = torch.Generator().manual_seed(0x5EED)
    return torch.rand(PROBE_POINTS, dim, generator=g, dtype=torch.float64).to(
        device=clf.examples.device, dtype=clf.examples.dtype)


@torch.no_grad()
def snapshot(clf) -> Tensor:
    """``[P, K, M]``: every slot's logit at the :func:`probe` points."""
    points = probe(clf, clf.examples.shape[-1])
    logits = clf.logit(points.expand(clf.population, -1, -1))  # [P, M, K]
    return logits.transpose(1, 2).detach().clone()


def _own_slot_logits(clf, examples: Tensor) -> Tensor:
    """Slot k's logit at slot k's examples: ``examples [P, K, L, D] -> [P, K, L]`` (by the
    model's ``own_logits`` where it has one: a per-slot model need not run every slot)."""
    if hasattr(clf, "own_logits"):
        return clf.own_logits(examples, torch.arange(examples.shape[0]))
    P, K, L, D = examples.shape
    z = clf.logit(examples.reshape(P, K * L, D)).reshape(P, K, L, K)
    return z.diagonal(dim1=1, dim2=3).permute(0, 2, 1)  # [P, L, K] -> [P, K, L]


def check_fittable(clf) -> None:
    """``ValueError`` (one line) for a subclass whose own model ``fit`` cannot train: it
    overrides ``logit`` or ``phi``, keeps the built-in ``fit``, and has no parameter with
    ``requires_grad`` (the built-in ``weight``/``bias`` have none: their closed-form fit serves
    the built-in model only). Skill-chaining discovery checks as it is built, so a run does not
    fail at its first fit; a bank whose sets are only used (given options) is not checked."""
    from .initiation import InitiationClassifier

    if clf.builtin_model() or type(clf).fit is not InitiationClassifier.fit:
        return
    if not any(p.requires_grad for p in clf.parameters()):
        raise ValueError(
            f"{type(clf).__name__} overrides logit or phi but has no parameter with "
            "requires_grad=True, so fit has nothing to train: give it parameters of its own "
            "(an nn.Module or nn.Parameter) or override fit")


def gradient_fit(clf, mask: Tensor, length: int) -> None:
    """``clf.sweeps`` optimizer steps on the summed per-slot mean log-loss of the slots in
    ``mask [P, K]`` over their first ``length`` stored places. Raises ``ValueError`` if the
    model has nothing to train."""
    params = [p for p in clf.parameters() if p.requires_grad]
    if not params:  # discovery refused such a set up front (check_fittable); a direct call
        raise ValueError(f"{type(clf).__name__} has no parameter with requires_grad=True: "
                         "nothing to fit")  # fmt: skip
    # A model with own_logits(examples, agents) computes only the agents that fit (episodes
    # end a few agents at a time); the others' parameters get no gradient, so no step.
    rows = mask.any(-1).nonzero()[:, 0] if hasattr(clf, "own_logits") else None
    pick = slice(None) if rows is None else rows
    examples = clf.examples[pick, :, :length]
    y = clf.labels[pick, :, :length].to(examples.dtype)
    count, mask = clf.count[pick], mask[pick]
    stored = (torch.arange(length, device=y.device) < count[..., None]) & mask[..., None]
    s = stored.to(y.dtype)
    if clf.balanced:  # each class's examples share half of a slot's loss
        positives = (s * y).sum(-1, keepdim=True)
        negatives = s.sum(-1, keepdim=True) - positives
        weight = torch.where(y > 0, 0.5 / positives.clamp(min=1.0), 0.5 / negatives.clamp(min=1.0))
    else:
        weight = 1.0 / s.sum(-1, keepdim=True).clamp(min=1.0)
    weight = weight * s
    optimizer = clf.make_optimizer(params)
    for _ in range(clf.sweeps):
        optimizer.zero_grad()
        z = _own_slot_logits(clf, examples) if rows is None else clf.own_logits(examples, rows)
        loss = functional.binary_cross_entropy_with_logits(z, y, weight=weight, reduction="sum")
        loss.backward()
        optimizer.step()


@torch.no_grad()
def points_logit(clf, agent: int, slot: int, points: Tensor) -> Tensor:
    """``[N]``: slot ``slot``'s logit at ``points [N, D]`` for agent ``agent``, through the
    model's logit (the points go to every agent's row, the others discarded: P times the work,
    fine for images)."""
    return clf.logit(points.expand(clf.population, -1, -1))[int(agent), :, int(slot)]
