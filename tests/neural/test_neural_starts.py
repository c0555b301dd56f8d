"""The default preset's two starts with neural heads (issue 53): a joining option's value
(``value_start="agent"``) and policy (``policy_start="top-level"``) fitted from the agent's own
values in the written head's last layer (``fit_values``)."""

from __future__ import annotations

import pytest
import torch

from skillchain_torch.discovery.gestation import fit_grid, fitted_starts, grid_values
from skillchain_torch.features import FourierBasis
from skillchain_torch.modules import LinearQHead, MLPQHead
from skillchain_torch.options import FourierOptionQHead, MLPOptionQHead
from skillchain_torch.trainers import PopulationTrainer, TrainConfig

A = 5


def trained_like_top(population=3, slots=2, seed=0):
    """An MLP top head whose primitive values vary over the states (random output weights)."""
    top = MLPQHead(num_features=4, num_decisions=A + slots, population=population, hidden=16,
                   seed=seed)
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        top.weights[-1].copy_(torch.randn(top.weights[-1].shape, generator=g))
        top.biases[-1].copy_(torch.randn(top.biases[-1].shape, generator=g))
    return top


def test_value_start_fits_the_agents_state_value_plus_the_bonus_only_where_asked():
    top = trained_like_top()
    before = {k: v.clone() for k, v in top.state_dict().items()}
    join = torch.tensor([[False, True], [False, False], [True, False]])
    grid = fit_grid(4)
    fitted_starts(join, top, None, torch.nn.Identity(), grid, A, value_bonus=100.0, policy=False)
    q = top(grid[:, None, :].expand(-1, 3, -1)).detach().to(torch.float64)  # [N, P, D]
    target = q[..., :A].amax(-1) + 100.0
    for p, k in join.nonzero().tolist():
        err = (q[:, p, A + k] - target[:, p]).abs()
        scale = target[:, p].abs().mean()
        assert float(err.mean()) < 0.05 * float(scale), (p, k)
    # Nothing else moved: the other decisions, agent 1, and every hidden layer.
    after = top.state_dict()
    for key in before:
        if key.startswith("weights.") or key.startswith("biases."):
            last = key.endswith(f".{len(top.weights) - 1}")
            if not last:
                assert torch.equal(before[key], after[key]), key
    assert torch.equal(before["weights.2"][1], after["weights.2"][1])
    assert torch.equal(before["weights.2"][0][:, [0, 1, 2, 3, 4, 5]],
                       after["weights.2"][0][:, [0, 1, 2, 3, 4, 5]])
    assert top.writes.tolist() == [1, 0, 1]  # a learner re-copies these agents' targets


@pytest.mark.parametrize("option_head", ["mlp", "fourier"])
def test_policy_start_copies_the_agents_greedy_action_into_the_option(option_head):
    top = trained_like_top()
    heads = {"mlp": MLPOptionQHead(population=3, slots=2, hidden=32, layers=2),
             "fourier": FourierOptionQHead(population=3, slots=2, order=3)}
    head = heads[option_head]
    join = torch.tensor([[True, False], [False, False], [False, True]])
    grid = fit_grid(4)
    fitted_starts(join, top, head, torch.nn.Identity(), grid, A, value_bonus=None, policy=True)
    states = torch.rand(500, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    agent = top(states[:, None, :].expand(-1, 3, -1)).detach()[..., :A].argmax(-1)  # [N, P]
    option = torch.stack([head(s.expand(3, 4)) for s in states])  # [N, P, K, A]
    for p, k in join.nonzero().tolist():
        same = (option[:, p, k].argmax(-1) == agent[:, p]).to(torch.float64).mean()
        assert float(same) > 0.8, (p, k, float(same))
    assert float(option[:, 1].abs().max()) == 0.0  # agent 1 joined nothing: still zero


def test_a_fourier_top_level_fits_a_neural_option_the_same_way():
    basis = FourierBasis(4, 2)
    top = LinearQHead(num_features=basis.num_features, num_decisions=A + 1, population=1)
    top.weight.data[0, 3, 1] = 50.0  # Q(s, a=3) grows along the first cosine feature
    top.weight.data[0, 1, 0] = 10.0
    head = MLPOptionQHead(population=1, slots=1, hidden=32, layers=2)
    fitted_starts(torch.tensor([[True]]), top, head, basis, fit_grid(4), A, None, True)
    states = fit_grid(4)[::7]
    agent = grid_values(top, basis(states), 0)[:, :A].argmax(-1)
    option = torch.stack([head(s[None])[0, 0] for s in states]).argmax(-1)
    assert float((agent == option).to(torch.float64).mean()) > 0.9


def neural_default(runs=2, episodes=6, seed=0):
    return TrainConfig(agent="skill-chaining", map="pinball_box", runs=runs, episodes=episodes,
                       max_episode_steps=300, top_head="mlp", option_head="mlp",
                       initiation="mlp", gestation=1, seed=seed)


def test_the_default_preset_trains_neural_heads_and_a_joined_option_starts_from_the_agent():
    trainer = PopulationTrainer(neural_default())
    assert (trainer.agent.discovery.policy_start, trainer.agent.discovery.value_start) == (
        "top-level", "agent")
    trainer.train()
    joined = [e for e in trainer.agent.discovery.log if e.kind == "joined"]
    assert joined, "no option joined: the test needs gestation to end"
    assert int(trainer.agent.q_head.writes.sum()) >= 2 * len(joined)  # set_values, then the fit
    again = PopulationTrainer(neural_default())
    again.train()
    assert again.returns.tolist() == trainer.returns.tolist()  # the fits draw no numbers
