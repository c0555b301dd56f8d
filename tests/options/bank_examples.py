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


def random_batches(clf, rounds, seed=5):
    """Add ``rounds`` random batches of 1-11 examples (about 80% positive) to random agents
    and slots of a two-agent, two-slot ``clf``: the stores' torch and compiled paths must agree."""
    gen = torch.Generator().manual_seed(seed)
    for _ in range(rounds):
        n = int(torch.randint(1, 12, (1,), generator=gen))
        x = torch.rand(n, 4, dtype=F64, generator=gen)
        labels = torch.rand(n, generator=gen) < 0.8
        agents = torch.randint(0, 2, (n,), generator=gen)
        clf.add_examples(agents, torch.randint(0, 2, (n,), generator=gen), x, labels)
    return clf


def compiled_stores_agree(rounds, **settings):
    """Run :func:`random_batches` on a torch-path and a compiled classifier (two agents, two
    slots, 16 places, ``settings``), assert their stores are the same bits; the compiled one."""
    stores = []
    for native in (False, True):
        clf = InitiationClassifier(population=2, slots=2, capacity=16, sweeps=0, **settings)
        clf.set_native(native)
        stores.append(random_batches(clf, rounds))
    torch_path, compiled = stores
    for name in ("examples", "labels", "count", "seen"):
        assert torch.equal(getattr(torch_path, name), getattr(compiled, name)), name
    return compiled
