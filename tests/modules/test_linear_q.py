"""LinearQHead and the batch-invariant reductions it is built on."""

import doctest
import importlib

import pytest
import torch

from skillchain_torch.invariant import rowwise_dot, rowwise_sum
from skillchain_torch.modules import LinearQHead

F64 = torch.float64


def random_head(population, decisions, features, seed=0):
    head = LinearQHead(features, decisions, population)
    gen = torch.Generator().manual_seed(seed)
    head.weight.copy_(torch.randn(head.weight.shape, dtype=F64, generator=gen))
    return head


def test_doctest():
    module = importlib.import_module("skillchain_torch.modules.linear_q")
    assert doctest.testmod(module).failed == 0


def test_weight_is_a_zero_buffer_in_state_dict():
    head = LinearQHead(num_features=625, num_decisions=5 + 4, population=3)
    assert head.weight.shape == (3, 9, 625) and head.weight.dtype == F64
    assert not bool(head.weight.any())
    assert list(head.parameters()) == []
    assert set(head.state_dict()) == {"weight"}
    assert "population=3" in repr(head)


def test_forward_is_the_dot_product_and_q_value_gathers_it_bitwise():
    head = random_head(4, 6, 50)
    phi = torch.rand(4, 50, dtype=F64)
    q = head(phi)
    expected = torch.stack([head.weight[p] @ phi[p] for p in range(4)])
    assert torch.allclose(q, expected, rtol=1e-13)
    for d in range(6):
        decision = torch.full((4,), d)
        assert torch.equal(head.q_value(phi, decision), q[:, d])
    mixed = torch.tensor([5, 0, 3, 3])
    assert torch.equal(head.q_value(phi, mixed), q.gather(1, mixed[:, None])[:, 0])


@pytest.mark.parametrize(("decisions", "features"), [(9, 1296), (25, 1296), (2, 40_000)])
def test_population_invariance(decisions, features):
    population = 5
    together = random_head(population, decisions, features)
    phi = torch.rand(population, features, dtype=F64, generator=torch.Generator().manual_seed(3))
    decision = torch.arange(population) % decisions
    q_all, q_sa = together(phi), together.q_value(phi, decision)
    for p in range(population):
        alone = LinearQHead(features, decisions, 1)
        alone.weight.copy_(together.weight[p : p + 1])
        assert torch.equal(alone(phi[p : p + 1])[0], q_all[p])
        assert torch.equal(alone.q_value(phi[p : p + 1], decision[p : p + 1])[0], q_sa[p])


def test_rowwise_sum_single_row_large_and_strided():
    gen = torch.Generator().manual_seed(0)
    x = torch.randn(5, 50_000, dtype=F64, generator=gen) * 1e3
    rows = rowwise_sum(x)
    for p in range(5):
        # A lone 50k-element row is where a plain .sum() splits the work across threads.
        assert torch.equal(rowwise_sum(x[p : p + 1])[0], rows[p])
        assert torch.equal(rowwise_sum(x[p]), rows[p])
    strided = x.T.contiguous().T  # same values, feature dim not contiguous
    assert torch.equal(rowwise_sum(strided), rows)
    assert torch.equal(rowwise_dot(x, torch.ones_like(x)), rows)


def test_add_to_decision_touches_only_masked_rows():
    head = random_head(3, 4, 5)
    before = head.weight.clone()
    increment = torch.ones(3, 5, dtype=F64)
    head.add_to_decision(
        torch.tensor([2, -1, 0]), increment, mask=torch.tensor([True, False, True])
    )
    expected = before.clone()
    expected[0, 2] += 1
    expected[2, 0] += 1
    assert torch.equal(head.weight, expected)


def test_shape_check():
    head = LinearQHead(4, 2, 3)
    with pytest.raises(ValueError):
        head(torch.zeros(2, 4, dtype=F64))


@pytest.mark.parametrize("share", [0.2, 0.9])  # the gather path and the whole-population path
def test_forward_rows_and_forward_mask_equal_forward_bitwise_where_asked(share):
    population, decisions = 8, 9
    head = random_head(population, decisions, 625, seed=4)
    gen = torch.Generator().manual_seed(6)
    phi = torch.rand(population, 625, dtype=F64, generator=gen)
    full = head(phi)
    rows = torch.rand(population, generator=gen) < share
    rows[0] = True
    q = head.forward_rows(phi, rows, decisions=6)
    assert torch.equal(q[rows, :6], full[rows, :6])
    assert not bool(q[~rows].any()) and not bool(q[:, 6:].any())
    need = torch.rand(population, decisions, generator=gen) < 0.3
    need[:, :5] = rows[:, None]
    q = head.forward_mask(phi, need, dense=5)
    assert torch.equal(q[need], full[need])
    assert not bool(q[~need].any())
    for p in range(population):  # one agent alone gets the same bits
        alone = LinearQHead(625, decisions, 1)
        alone.weight.copy_(head.weight[p : p + 1])
        assert torch.equal(alone.forward_mask(phi[p : p + 1], need[p : p + 1], dense=5)[0], q[p])
    with pytest.raises(ValueError, match="need must be"):
        head.forward_mask(phi, need[:, :5])
