"""Option banks for the OptionBank tests: a trained bank with options in several states.

Example:
    >>> bank = trained_bank(population=2)
    >>> bank.status[0].tolist(), bank.classifier.trained[:, 0].tolist()
    ([2, 1, 0, 0], [True, True])
"""

import torch

from skillchain_torch.options import (
    FourierOptionQHead,
    InitiationClassifier,
    OptionBank,
    OptionStatus,
)

F64 = torch.float64


def rand(shape, seed):
    return torch.rand(shape, dtype=F64, generator=torch.Generator().manual_seed(seed))


def trained_bank(population=3, slots=4, seed=0, q_head=None):
    """A bank with options in various states, weights and classifier data."""
    q_head = q_head or FourierOptionQHead(population, slots, order=1)
    bank = OptionBank(
        population, slots, q_head, InitiationClassifier(population, slots, capacity=32, sweeps=100)
    )
    everyone = torch.ones(population, dtype=torch.bool)
    bank.allocate(everyone, target_event=0, episode=1)
    bank.allocate(everyone, parent=0, episode=2)
    gen = torch.Generator().manual_seed(seed)
    if isinstance(q_head, FourierOptionQHead):
        q_head.weight.copy_(torch.randn(q_head.weight.shape, dtype=F64, generator=gen))
    x = torch.rand(20, 4, dtype=F64, generator=gen)
    for p in range(population):
        bank.classifier.add_examples(p, 0, x, x[:, 0] < 0.5 + 0.1 * p)
    bank.classifier.fit()
    bank.set_status(torch.tensor([[True, False, False, False]] * population),
                    OptionStatus.LEARNING)  # fmt: skip
    return bank
