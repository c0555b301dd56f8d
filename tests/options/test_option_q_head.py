"""Option Q-heads: closed-form Fourier TD step, masks, resets, MLP drop-in, invariance."""

import doctest
import importlib

import pytest
import torch

from skillchain_torch.features import FourierBasis
from skillchain_torch.options import FourierOptionQHead, MLPOptionQHead, OptionQHead

F64 = torch.float64


def random_obs(population, seed=0):
    return torch.rand(population, 4, dtype=F64, generator=torch.Generator().manual_seed(seed))


def random_fourier(population, slots=3, seed=0, **kwargs):
    head = FourierOptionQHead(population, slots, **kwargs)
    gen = torch.Generator().manual_seed(seed)
    head.weight.copy_(torch.randn(head.weight.shape, dtype=F64, generator=gen))
    return head


def test_doctest():
    module = importlib.import_module("skillchain_torch.options.q_head")
    assert doctest.testmod(module).failed == 0


def test_fourier_head_shapes_and_zero_init():
    head = FourierOptionQHead(population=3, slots=8)
    assert isinstance(head, OptionQHead)
    assert head.weight.shape == (3, 8, 5, 256) and not bool(head.weight.any())
    assert list(head.parameters()) == []
    q = head(random_obs(3))
    assert q.shape == (3, 8, 5) and q.dtype == F64 and not bool(q.any())


def test_fourier_forward_is_the_dot_product_and_q_value_gathers_it():
    head = random_fourier(2, slots=3, order=2)
    obs = random_obs(2)
    phi = FourierBasis(4, 2)(obs)
    q = head(obs)
    expected = torch.einsum("pkaf,pf->pka", head.weight, phi)
    assert torch.allclose(q, expected, rtol=1e-12)
    action = torch.tensor([4, 1])
    assert torch.equal(head.q_value(obs, action), q[torch.arange(2), :, action])


def test_fourier_td_update_matches_hand_computation():
    head = random_fourier(2, slots=3, order=1, alpha=0.25)
    obs, action = random_obs(2, seed=1), torch.tensor([2, 0])
    target = torch.tensor([[1.0, -3.0, 7.0], [0.5, 2.0, 4.0]], dtype=F64)
    mask = torch.tensor([[True, False, True], [False, True, False]])
    before = head.weight.clone()
    phi = FourierBasis(4, 1)(obs)
    delta = head.td_update(obs, action, target, mask)
    expected = before.clone()
    for p in range(2):
        for k in range(3):
            if mask[p, k]:
                q_sa = float((before[p, k, action[p]] * phi[p]).sum())
                assert delta[p, k].item() == pytest.approx(target[p, k].item() - q_sa, abs=1e-12)
                expected[p, k, action[p]] += 0.25 * delta[p, k] * phi[p]
            else:
                assert delta[p, k].item() == 0.0
    assert torch.allclose(head.weight, expected, rtol=0, atol=1e-13)
    # Only masked (slot, action) rows moved; everything else is bit-for-bit unchanged.
    changed = (head.weight != before).any(-1)
    allowed = torch.zeros_like(changed)
    for p in range(2):
        allowed[p, :, action[p]] = mask[p]
    assert not bool((changed & ~allowed).any())


def test_fourier_update_ignores_nan_targets_and_bad_actions_off_mask():
    head = random_fourier(2)
    before = head.weight.clone()
    target = torch.full((2, 3), float("nan"), dtype=F64)
    mask = torch.zeros(2, 3, dtype=torch.bool)
    delta = head.td_update(random_obs(2), torch.tensor([-1, 9]), target, mask)
    assert torch.equal(head.weight, before) and not bool(delta.any())


def test_reset_slot_zeroes_only_that_slot():
    head = random_fourier(3, slots=4)
    before = head.weight.clone()
    head.reset_slot(torch.tensor([True, False, True]), torch.tensor([1, 0, 3]))
    assert not bool(head.weight[0, 1].any()) and not bool(head.weight[2, 3].any())
    keep = torch.ones(3, 4, dtype=torch.bool)
    keep[0, 1] = keep[2, 3] = False
    assert torch.equal(head.weight[keep], before[keep])
    head.reset_slot(1, 2)
    assert not bool(head.weight[1, 2].any())


def test_shape_errors():
    head = FourierOptionQHead(2, 3, order=1)
    with pytest.raises(ValueError, match="obs must be"):
        head(torch.zeros(3, 4, dtype=F64))
    with pytest.raises(ValueError, match="target must be"):
        head.td_update(random_obs(2), torch.tensor([0, 0]), torch.zeros(2, 2), torch.ones(2, 3))
    with pytest.raises(ValueError, match="actions must lie"):
        head.td_update(random_obs(2), torch.tensor([0, 5]), torch.zeros(2, 3),
                       torch.ones(2, 3, dtype=torch.bool))  # fmt: skip


def test_fourier_population_invariance():
    population, slots = 4, 8
    together = random_fourier(population, slots, seed=3)
    alone = [together.select_agents([p]) for p in range(population)]
    gen = torch.Generator().manual_seed(5)
    for _ in range(5):
        obs = torch.rand(population, 4, dtype=F64, generator=gen)
        action = torch.randint(0, 5, (population,), generator=gen)
        target = torch.randn(population, slots, dtype=F64, generator=gen) * 100
        mask = torch.rand(population, slots, generator=gen) < 0.6
        q = together(obs)
        delta = together.td_update(obs, action, target, mask)
        for p, head in enumerate(alone):
            sl = slice(p, p + 1)
            assert torch.equal(head(obs[sl])[0], q[p])
            assert torch.equal(head.td_update(obs[sl], action[sl], target[sl], mask[sl])[0],
                               delta[p])  # fmt: skip
    for p, head in enumerate(alone):
        assert torch.equal(head.weight[0], together.weight[p])


def test_select_agents_replicates():
    head = random_fourier(3)
    copies = head.select_agents([1, 1])
    assert copies.population == 2
    assert torch.equal(copies.weight[0], head.weight[1]) and torch.equal(
        copies.weight[1], head.weight[1]
    )


# ----------------------------------------------------------------------------------- MLP head
def test_mlp_head_interface_and_zero_initial_values():
    head = MLPOptionQHead(population=3, slots=4, hidden=16)
    assert isinstance(head, OptionQHead)
    q = head(random_obs(3))
    assert q.shape == (3, 4, 5) and not bool(q.any())  # output layer starts at zero
    first = head.params["0__weight"]
    assert first.shape == (3, 4, 16, 4)
    assert not torch.equal(first[0, 0], first[0, 1]) and not torch.equal(first[0, 0], first[1, 0])
    assert float(first.abs().max()) <= 0.5  # U(-1/sqrt(4), 1/sqrt(4))


def test_mlp_td_update_reduces_error_and_touches_only_masked_slots():
    head = MLPOptionQHead(population=2, slots=3, hidden=16, lr=0.01)
    obs, action = random_obs(2), torch.tensor([1, 3])
    target = torch.tensor([[1.0, 2.0, -1.0], [0.5, 0.0, 3.0]], dtype=F64)
    mask = torch.tensor([[True, False, True], [False, False, True]])
    before = {k: v.clone() for k, v in head.params.items()}
    first = head.td_update(obs, action, target, mask)
    for _ in range(50):
        delta = head.td_update(obs, action, target, mask)
    assert bool((delta.abs() < first.abs())[mask].all())
    assert not bool(delta[~mask].any())
    for key, value in head.params.items():
        assert torch.equal(value[~mask], before[key][~mask])
        assert not torch.equal(value[mask], before[key][mask]) or key.endswith("0__bias")


def test_mlp_reset_slot_restores_zero_output_and_new_hidden_weights():
    head = MLPOptionQHead(population=2, slots=2, hidden=8, lr=0.05)
    obs = random_obs(2)
    mask = torch.ones(2, 2, dtype=torch.bool)
    for _ in range(5):
        head.td_update(obs, torch.tensor([0, 1]), torch.ones(2, 2, dtype=F64), mask)
    hidden = head.params["0__weight"].clone()
    head.reset_slot(1, 0)
    q = head(obs)
    assert not bool(q[1, 0].any()) and bool(q[0, 0].any())
    assert not torch.equal(head.params["0__weight"][1, 0], hidden[1, 0])  # fresh draw
    assert torch.equal(head.params["0__weight"][0], hidden[0])


def test_mlp_initial_weights_depend_only_on_the_agent_seed():
    together = MLPOptionQHead(population=4, slots=3, hidden=8, seed=10)
    alone = MLPOptionQHead(population=1, slots=3, hidden=8, seed=torch.tensor([12]))
    for key, value in together.params.items():
        assert torch.equal(alone.params[key][0], value[2])
    copy = together.select_agents([2, 2])
    assert torch.equal(copy.params["0__weight"][1], together.params["0__weight"][2])


def test_slot_values_rows_is_slot_values_of_those_rows_bitwise():
    head = random_fourier(5, 4, seed=8)
    gen = torch.Generator().manual_seed(9)
    code = head.encode(torch.rand(5, 4, dtype=F64, generator=gen))
    slot = torch.tensor([2, -1, 0, 3, 1])
    index = torch.tensor([0, 2, 3])
    rows = head.slot_values_rows(code, slot, index)
    assert torch.equal(rows, head.slot_values(code, slot)[index])
