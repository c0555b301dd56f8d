"""Linear SMDP Sarsa: hand-computed steps, gamma^k, terminal, masks, invariance, convergence."""

import doctest
import importlib

import torch

from skillchain_torch.features import FourierBasis
from skillchain_torch.modules import LinearQHead
from skillchain_torch.objectives import SarsaUpdate, discount, smdp_td_error

F64 = torch.float64


def t(values, dtype=F64):
    return torch.tensor(values, dtype=dtype)


def head_with(weight):
    weight = t(weight)
    head = LinearQHead(weight.shape[2], weight.shape[1], weight.shape[0])
    head.weight.copy_(weight)
    return head


def test_doctest():
    module = importlib.import_module("skillchain_torch.objectives.sarsa")
    assert doctest.testmod(module).failed == 0


def test_hand_computed_single_step():
    head = head_with([[[1.0, 2.0, 0.0], [0.5, 0.0, -1.0]]])
    phi, next_phi = t([[1.0, 0.5, 2.0]]), t([[0.0, 1.0, 1.0]])
    update = SarsaUpdate(alpha=0.1, gamma=1.0)
    delta = update(
        head, phi, torch.tensor([0]), t([-5.0]), torch.tensor([1]), next_phi, torch.tensor([1]),
        torch.tensor([False]),
    )  # fmt: skip
    # Q(s, 0) = 1 + 1 = 2; Q(s', 1) = -1; delta = -5 - 1 - 2 = -8.
    assert delta.tolist() == [-8.0]
    expected = [[1.0 - 0.8, 2.0 - 0.4, 0.0 - 1.6], [0.5, 0.0, -1.0]]
    assert torch.allclose(head.weight[0], t(expected), rtol=0, atol=1e-15)


def test_k_step_discount_is_gamma_to_the_k():
    gamma = 0.9
    head = head_with([[[0.0, 0.0], [2.0, 3.0]]] * 3)
    phi = t([[1.0, 1.0]] * 3)
    duration = torch.tensor([1, 3, 17])
    delta = SarsaUpdate(alpha=0.0, gamma=gamma)(
        head, phi, torch.zeros(3, dtype=torch.int64), t([-1.0, -7.0, -40.0]), duration, phi,
        torch.ones(3, dtype=torch.int64), torch.zeros(3, dtype=torch.bool),
    )  # fmt: skip
    expected = [r + gamma**k * 5.0 for r, k in [(-1.0, 1), (-7.0, 3), (-40.0, 17)]]
    assert delta.tolist() == expected


def test_discount_matches_python_pow_in_any_layout():
    for gamma in (0.99, 0.9, 0.999, 1.0):
        k = torch.randperm(3000)
        expected = torch.tensor([gamma ** int(i) for i in k], dtype=F64)
        assert torch.equal(discount(gamma, k), expected)
        assert torch.equal(discount(gamma, k[7:8]), expected[7:8])
    assert discount(0.5, torch.tensor([[0, 1], [2, 3]])).tolist() == [[1.0, 0.5], [0.25, 0.125]]


def test_terminal_ignores_bootstrap():
    delta = smdp_td_error(
        reward=t([10_000.0, -1.0]), duration=torch.tensor([4, 1]), q_sa=t([3.0, 3.0]),
        q_next=t([torch.inf, 2.0]), terminal=torch.tensor([True, False]), gamma=0.5,
    )  # fmt: skip
    assert delta.tolist() == [10_000.0 - 3.0, -1.0 + 0.5 * 2.0 - 3.0]


def test_inactive_agents_unchanged_and_report_zero():
    head = head_with(torch.randn(3, 4, 5).tolist())
    before = head.weight.clone()
    phi = torch.rand(3, 5, dtype=F64)
    delta = SarsaUpdate(alpha=0.5)(
        head, phi, torch.tensor([1, -1, 2]), t([-1.0, -1.0, -1.0]), torch.tensor([1, 1, 1]), phi,
        torch.tensor([0, -1, 3]), torch.tensor([False, False, True]),
        active=torch.tensor([True, False, True]),
    )  # fmt: skip
    assert delta[1] == 0 and delta[0] != 0 and delta[2] != 0
    assert torch.equal(head.weight[1], before[1])
    changed = (head.weight != before).any(-1)
    assert changed.tolist() == [
        [False, True, False, False],
        [False] * 4,
        [False, False, True, False],
    ]


def test_step_size_scale_per_feature():
    basis = FourierBasis(2, 1)
    scale = basis.step_size_scale()
    head = LinearQHead(4, 1, 1)
    phi = t([[1.0, 1.0, 1.0, 1.0]])
    update = SarsaUpdate(alpha=0.2, step_size_scale=scale)
    # TorchRL-style [P, 1] rewards, durations and dones are accepted too.
    delta = update(
        head,
        phi,
        torch.tensor([0]),
        t([[-1.0]]),
        torch.tensor([[1]]),
        phi,
        torch.tensor([0]),
        torch.tensor([[True]]),
    )
    assert delta.tolist() == [-1.0]
    assert torch.equal(head.weight[0, 0], (0.2 * scale) * -1.0)
    assert head.weight[0, 0, 3] != head.weight[0, 0, 0]


def test_population_invariance_over_many_updates():
    population, decisions, features = 5, 7, 256
    gen = torch.Generator().manual_seed(0)
    scale = FourierBasis(4, 3).step_size_scale()
    update = SarsaUpdate(alpha=0.01, gamma=0.99, step_size_scale=scale)
    together = LinearQHead(features, decisions, population)
    alone = [LinearQHead(features, decisions, 1) for _ in range(population)]
    for _ in range(30):
        phi = torch.rand(population, features, dtype=F64, generator=gen)
        next_phi = torch.rand(population, features, dtype=F64, generator=gen)
        batch = dict(
            decision=torch.randint(decisions, (population,), generator=gen),
            reward=torch.randn(population, dtype=F64, generator=gen) * 10,
            duration=torch.randint(1, 250, (population,), generator=gen),
            next_decision=torch.randint(decisions, (population,), generator=gen),
            terminal=torch.rand(population, generator=gen) < 0.2,
            active=torch.rand(population, generator=gen) < 0.8,
        )
        delta = update(together, phi, next_phi=next_phi, **batch)
        for p, head in enumerate(alone):
            mine = update(
                head, phi[p : p + 1], next_phi=next_phi[p : p + 1],
                **{key: value[p : p + 1] for key, value in batch.items()},
            )  # fmt: skip
            assert torch.equal(mine[0], delta[p])
    for p, head in enumerate(alone):
        assert torch.equal(head.weight[0], together.weight[p])


def test_reduces_td_error_on_a_tiny_chain():
    # s0 --(d=0, R=-1)--> s1 --(d=0, R=-1, then a 3-step option d=1 worth R=-2)--> goal.
    phi = torch.eye(3, dtype=F64)[None]  # one-hot states
    head = LinearQHead(3, 2, 1)
    update = SarsaUpdate(alpha=0.5, gamma=1.0)
    transitions = [
        (0, 0, -1.0, 1, 1, 0, False),  # (s, d, R, k, s', d', terminal)
        (1, 0, -1.0, 1, 2, 0, True),
        (0, 1, -2.0, 3, 2, 0, True),
    ]
    first_sweep = None
    for sweep in range(40):
        errors = []
        for s, d, r, k, s2, d2, term in transitions:
            delta = update(
                head, phi[:, s], torch.tensor([d]), t([r]), torch.tensor([k]), phi[:, s2],
                torch.tensor([d2]), torch.tensor([term]),
            )  # fmt: skip
            errors.append(abs(delta.item()))
        if sweep == 0:
            first_sweep = sum(errors)
    assert sum(errors) < 1e-6 < first_sweep
    assert torch.allclose(head.weight[0, :, :2], t([[-2.0, -1.0], [-2.0, 0.0]]), atol=1e-6)


def test_given_next_value_is_the_same_update_as_valuing_next_phi():
    gen = torch.Generator().manual_seed(2)
    weight = torch.randn(6, 4, 30, dtype=F64, generator=gen)
    heads = [head_with(weight.tolist()) for _ in range(2)]
    phi, next_phi = (torch.rand(6, 30, dtype=F64, generator=gen) for _ in range(2))
    decision, next_decision = torch.tensor([0, 1, 2, 3, 0, 1]), torch.tensor([3, 3, 1, 0, 2, 2])
    args = dict(reward=t([-1.0, -5.0, 3.0, 0.0, 2.0, -1.0]),
                duration=torch.tensor([1, 2, 1, 7, 1, 1]),
                terminal=torch.tensor([False, False, True, False, False, False]),
                active=torch.tensor([True, True, True, False, True, True]))
    update = SarsaUpdate(alpha=0.01, gamma=0.9)
    plain = update(heads[0], phi, decision, next_phi=next_phi, next_decision=next_decision,
                   **args)  # fmt: skip
    value = heads[1].q_value(next_phi, next_decision)
    given = update(heads[1], phi, decision, next_phi=None, next_decision=next_decision,
                   next_value=value, **args)  # fmt: skip
    assert torch.equal(plain, given) and bool(plain[:3].ne(0).all()) and float(plain[3]) == 0.0
    assert torch.equal(heads[0].weight, heads[1].weight)
    assert not torch.equal(heads[0].weight, weight)
