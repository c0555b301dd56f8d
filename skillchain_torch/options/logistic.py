"""Fitting an initiation set: gradient sweeps of logistic regression (paper section 5.1).

"A logistic regression classifier ... learning rate eta = 0.1 and 100 sweeps per new data
point": each sweep is one full-batch gradient step on the mean log-loss of a slot's stored
examples. :func:`logistic_sweeps` is that maths for a batch of slots, a pure function;
:class:`~skillchain_torch.options.InitiationClassifier` holds the examples and parameters.

Example:
    >>> import torch
    >>> x = torch.tensor([[[1.0, 0.0], [1.0, 1.0]]], dtype=torch.float64)   # 1 slot, 2 examples
    >>> params = logistic_sweeps(x, torch.tensor([[True, False]]), torch.ones(1, 2, dtype=bool),
    ...                          torch.zeros(1, 3, dtype=torch.float64), lr=1.0, sweeps=50)
    >>> params[0, 1].item() < 0                                  # feature 1 says "not in the set"
    True
"""

from __future__ import annotations

import torch
from torch import Tensor

from skillchain_torch.invariant import rowwise_sum

__all__ = ["logistic_sweeps", "sweep_terms"]


def logistic_sweeps(x: Tensor, labels: Tensor, stored: Tensor, params: Tensor, lr: float,
                    sweeps: int, balanced: bool = False) -> Tensor:  # fmt: skip
    """``sweeps`` full-batch gradient steps on the mean log-loss; the new parameters.

    Args:
        x: features ``[M, L, F]`` of M slots' L example places.
        labels: ``[M, L]`` bool (positive = in the set); stored: ``[M, L]`` bool, the places
            holding an example (the others weigh nothing).
        params: ``[M, F + 1]``, each slot's weights and then its intercept.
        lr: the learning rate; sweeps: gradient steps.
        balanced: weight the two classes equally (each class's examples share half the loss);
            otherwise the plain mean.

    Returns ``[M, F + 1]``. A slot's numbers depend on its own rows only, and ``L`` (the
    caller's choice) sets the length of every sum, so the caller keeps it independent of which
    slots are fitted together.

    Written for few tensor operations per sweep (six calls): the intercept rides as a last
    weight on a constant feature, each example's step ``lr * its weight in the mean`` (0 for
    empty places) is folded in once, and the loop carries the negated parameters ``v`` so that
    ``exp(x . v)`` is ``exp(-z)``: a sweep is ``g = s / (1 + exp(x . v)) - s y``
    (``= lr * weight * (sigmoid(z) - y)``), ``v += sum_l x_l g_l``. ``sigmoid`` itself is
    avoided: its vectorised and scalar paths differ in the last bit.
    """
    x, step, minus_step_y = sweep_terms(x, labels, stored, lr, balanced)
    xt = x.transpose(1, 2).contiguous()  # [M, F + 1, L] to reduce over the examples
    v = -params.to(x.dtype)  # [M, F + 1]
    # The same arithmetic as
    #   g = step / (1 + exp((x * v).sum(-1))) - step * y;  v = v + (xt * g).sum(-1)
    # in as few calls as possible, into buffers made once (vecdot is that product and sum;
    # addcdiv adds -step * y to step / (...), which is the same subtraction).
    z, g, dv = torch.empty_like(step), torch.empty_like(step), torch.empty_like(v)
    v_row, g_row = v.view(v.shape[0], 1, -1), g.view(g.shape[0], 1, -1)
    for _ in range(sweeps):
        torch.linalg.vecdot(x, v_row, out=z)  # x . v = -logit, [M, L]
        z.exp_().add_(1.0)
        torch.addcdiv(minus_step_y, step, z, out=g)
        torch.linalg.vecdot(xt, g_row, out=dv)  # sum over the examples, [M, F + 1]
        v.add_(dv)
    # Each sum above reduces a contiguous last dim with more than one row, so every row is
    # summed alone in a fixed order (see skillchain_torch.invariant).
    return -v


def sweep_terms(x: Tensor, labels: Tensor, stored: Tensor, lr: float,
                balanced: bool) -> tuple[Tensor, Tensor, Tensor]:  # fmt: skip
    """What every sweep of :func:`logistic_sweeps` reuses: ``(x1, step, minus_step_y)``.

    ``x1 [M, L, F + 1]``: the features with a constant 1 appended (the intercept's);
    ``step [M, L]``: ``lr`` times each example's weight in the loss (0 for empty places);
    ``minus_step_y``: ``-(step * y)``. Shared with the compiled sweeps
    (:mod:`~skillchain_torch.backends.initiation`), which start from the same numbers.
    """
    x = torch.cat([x, torch.ones_like(x[..., :1])], dim=-1)  # [M, L, F + 1]
    y = labels.to(x.dtype)
    zero = torch.zeros((), dtype=x.dtype, device=x.device)
    count = rowwise_sum(stored.to(x.dtype))
    if balanced:  # each example weighs 1 / (2 * its class's count)
        positives = rowwise_sum(torch.where(stored, y, zero))
        negatives = count - positives
        weight = torch.where(y > 0, 0.5 / positives.clamp(min=1.0)[:, None],
                             0.5 / negatives.clamp(min=1.0)[:, None])  # fmt: skip
    else:  # the plain mean
        weight = (1.0 / count)[:, None].expand_as(y)
    step = torch.where(stored, lr * weight, zero)  # [M, L]
    return x, step, -(step * y)
