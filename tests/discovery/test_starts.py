"""How a joining option starts: its policy (``policy_start``) and ``Q(s, o)`` (``value_start``).

The pure maths (the least-squares maps over the observation grid) is checked on functions it
must reproduce exactly; the rules through a corridor agent (see ``corridor.py``) whose top
level is set by hand and frozen, so the option's start can be compared with it.
"""

from __future__ import annotations

import pytest
import torch
from corridor import CORRIDOR, episode, make_agent, point

from skillchain_torch.discovery import SkillChaining
from skillchain_torch.discovery.gestation import StateValueFit, value_projection
from skillchain_torch.features import FourierBasis
from skillchain_torch.options import OptionBank, OptionStatus
from skillchain_torch.trainers import TrainConfig

F64 = torch.float64


def probe(n=50, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(n, 4, generator=g, dtype=F64)


# ------------------------------------------------------------------ pure maths
def test_projection_reproduces_a_function_the_option_basis_holds():
    top, option = FourierBasis(4, 2), FourierBasis(4, 1)
    shared = [i for i, c in enumerate(top.coefficients.tolist()) if max(c) <= 1]
    w = torch.zeros(top.num_features, dtype=F64)
    w[shared] = torch.linspace(-3.0, 5.0, len(shared), dtype=F64)  # only order-1 terms
    M = value_projection(top, option, points=5)
    s = probe()
    assert torch.allclose(option(s) @ (M @ w), top(s) @ w, atol=1e-9)


def test_projection_keeps_which_action_is_best_where_actions_differ_broadly():
    top, option = FourierBasis(4, 3), FourierBasis(4, 2)
    g = torch.Generator().manual_seed(1)
    w = 0.01 * torch.randn(5, top.num_features, generator=g, dtype=F64)  # small high-order noise
    w[:, 0] += torch.tensor([0.0, 1.0, 4.0, 2.0, 3.0], dtype=F64)  # action 2 best everywhere
    M = value_projection(top, option, points=5)
    s = probe()
    assert (top(s) @ w.T).argmax(-1).eq(2).all()
    assert (option(s) @ (w @ M.T).T).argmax(-1).eq(2).all()


def test_state_value_fit_is_the_best_action_where_one_dominates():
    basis = FourierBasis(4, 2)
    w = torch.zeros(5, basis.num_features, dtype=F64)
    w[3, 0], w[3, 1], w[1, 0] = 50.0, 2.0, -10.0  # Q(s, 3) = 50 + 2 cos(pi s_4) > Q(s, 1)
    fit = StateValueFit(basis, points=5)
    s = probe()
    assert torch.allclose(basis(s) @ fit(w), basis(s) @ w[3], atol=1e-8)


def test_projection_refuses_mismatched_dimensions():
    with pytest.raises(ValueError, match="dimension"):
        value_projection(FourierBasis(3, 2), FourierBasis(4, 1))


# ------------------------------------------------------------------ through the agent
def top_level(agent, crossing=True):
    """A hand-set top level (frozen: alpha 0) over the corridor's x (feature 8 of order 1 is
    cos(pi x)): action 4 = 10 + 6 cos(pi x) is best on the left; with ``crossing`` action
    0 = 10 - 6 cos(pi x) is best on the right, else action 0 = 0 and action 4 is best."""
    with torch.no_grad():
        w = agent.q_head.weight
        w.zero_()
        w[0, 4, 0], w[0, 4, 8] = 10.0, 6.0
        if crossing:
            w[0, 0, 0], w[0, 0, 8] = 10.0, -6.0


def join_goal_option(agent):
    episode(agent, CORRIDOR, terminated=True, first=True)  # creates slot 0
    episode(agent, [0.1, 0.2, 0.3], terminated=False)  # one episode of gestation: joins
    assert agent.bank.status[0, 0] == OptionStatus.LEARNING


def test_top_level_policy_start_copies_the_agents_greedy_policy():
    agent = make_agent(gestation=1, policy_start="top-level")
    top_level(agent)
    join_goal_option(agent)
    for x in (0.1, 0.3, 0.7, 0.95):
        s = point(x)
        mine = agent.q_head(agent.features(s))[0, :5]
        option = agent.bank.q_head(s)[0, 0]
        assert torch.allclose(option, mine, atol=1e-8)  # order 1 in both: exact
        assert int(option.argmax()) == int(mine.argmax())


def test_zero_policy_start_leaves_the_option_to_its_gestation_updates():
    agent = make_agent(gestation=1, option_alpha=0.0)  # no off-policy updates either
    top_level(agent)
    join_goal_option(agent)
    assert agent.bank.q_head.weight[0, 0].abs().max().item() == 0.0


def test_agent_value_start_is_the_best_primitive_plus_the_bonus():
    agent = make_agent(gestation=1, value_start="agent", value_bonus=7.0)
    top_level(agent, crossing=False)
    join_goal_option(agent)
    for x in (0.05, 0.5, 0.95):
        q = agent.q_head(agent.features(point(x)))[0]
        assert abs(float(q[5] - (q[:5].max() + 7.0))) < 1e-8  # max_a Q(s, a) is Q(s, 4) here
    # not the paper's one constant (the best sampled Q(s, d)) everywhere
    q_left, q_right = (agent.q_head(agent.features(point(x)))[0, 5] for x in (0.05, 0.95))
    assert float(q_left - q_right) > 10.0


def test_bad_starts_are_refused_by_name():
    bank = OptionBank.build(population=1, slots=2, order=1)
    with pytest.raises(ValueError, match="policy_start must be one of zero, top-level"):
        SkillChaining(bank, policy_start="copy")
    with pytest.raises(ValueError, match="value_start must be one of max-sample, agent"):
        SkillChaining(bank, value_start="best")
    with pytest.raises(ValueError, match="needs the agent's top-level features"):
        SkillChaining(bank, policy_start="top-level")  # no top_basis
    with pytest.raises(ValueError, match="policy_start must be one of"):
        TrainConfig(agent="skill-chaining", policy_start="copy").validate()
    with pytest.raises(ValueError, match="value_start must be one of"):
        TrainConfig(agent="skill-chaining", value_start="x").validate()
    with pytest.raises(ValueError, match="value_bonus must be finite"):
        TrainConfig(agent="skill-chaining", value_bonus=float("nan")).validate()


def test_configs_saved_before_the_starts_read_as_the_paper():
    data = TrainConfig(agent="skill-chaining").to_dict()
    for name in ("policy_start", "value_start", "value_bonus"):
        del data[name]
    cfg = TrainConfig.from_dict(data)
    assert (cfg.policy_start, cfg.value_start, cfg.value_bonus) == ("zero", "max-sample", 0.0)


def test_a_flat_run_does_not_differ_from_a_config_that_changes_option_settings():
    flat = TrainConfig(agent="flat", runs=2)
    other = TrainConfig(agent="flat", runs=2, policy_start="top-level", value_start="agent",
                        option_alpha=0.0, completion_reward=5.0, slots=3)
    assert flat.mismatches(other) == []
    assert flat.mismatches(TrainConfig(agent="flat", runs=3)) == ["runs"]
    sc = TrainConfig(agent="skill-chaining", runs=2)
    changed = TrainConfig(agent="skill-chaining", runs=2, policy_start="zero")
    assert sc.mismatches(changed) == ["policy_start"]  # skill chaining reads it
    assert "agent" in flat.mismatches(sc)
