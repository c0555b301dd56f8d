"""HierarchicalAgent in hand-built situations (issue 4, "Monitoring and proof"): an option takes
control, runs, ends and is credited with one SMDP update; where it may run and learn."""

from __future__ import annotations

import doctest

import hand_built
import pytest
import torch
from hand_built import F64, NO, make_agent, make_bank, obs, prefer_option

from skillchain_torch.agents import HierarchicalAgent
from skillchain_torch.envs.pinball import PinballEnv
from skillchain_torch.options import (
    FourierOptionQHead,
    InitiationClassifier,
    MLPOptionQHead,
    OptionBank,
    OptionStatus,
    RegionEvent,
)


def test_hand_built_doctest():
    assert doctest.testmod(hand_built).failed == 0


@pytest.mark.parametrize("gamma", [1.0, 0.9])
def test_option_takes_control_terminates_and_is_credited(gamma):
    agent = make_agent(make_bank(), gamma=gamma)
    prefer_option(agent)
    s0 = obs((0.6, 0.5, 0.5, 0.5))
    agent.begin(s0)
    assert agent.decisions.tolist() == [5] and agent.options.tolist() == [0]
    path = [obs((0.7, 0.4, 0.5, 0.5)), obs((0.8, 0.3, 0.5, 0.5)), obs((0.9, 0.2, 0.5, 0.5))]
    rewards = [-1.0, -5.0, -1.0]
    weights = []
    for s1, r in zip(path[:2], rewards[:2]):
        before = agent.q_head.weight.clone()
        agent.observe(s1, torch.tensor([r], dtype=F64))
        assert torch.equal(agent.q_head.weight, before)  # the option is still running
        assert agent.options.tolist() == [0] and agent.decisions.tolist() == [5]
        weights.append(before)
    phi0 = agent.features(s0)
    w = agent.q_head.weight.clone()
    q_s0 = (w[0, 5] * phi0[0]).sum()
    info = agent.transition(path[2], torch.tensor([rewards[2]], dtype=F64), NO, NO,
                            torch.tensor([True]))
    assert info["decision_ended"].tolist() == [True]
    assert info["duration"].tolist() == [3]
    R = rewards[0] + gamma * rewards[1] + gamma * gamma * rewards[2]
    assert info["decision_return"].item() == pytest.approx(R, abs=1e-12)
    d_next = int(agent.decision[0])
    q_next = (w[0, d_next] * agent.features(path[2])[0]).sum()
    delta = (R + gamma**3 * q_next) - q_s0
    assert info["smdp_delta"].item() == pytest.approx(delta.item(), rel=1e-12)
    expected = w.clone()
    expected[0, 5] += 0.01 * delta * phi0[0]
    torch.testing.assert_close(agent.q_head.weight, expected, rtol=0, atol=1e-12)
    # Only decision 5's row moved.
    changed = (agent.q_head.weight != w).any(-1)[0]
    assert changed.tolist() == [False] * 5 + [True]


def test_unavailable_option_is_never_chosen():
    P = 64
    bank = make_bank(population=P)
    agent = make_agent(bank, epsilon=1.0)  # always explore among the available decisions
    prefer_option(agent, value=1e6)
    outside = obs(*[(0.3, 0.5, 0.5, 0.5)] * P)
    agent.begin(outside)
    assert bool((agent.decisions < 5).all()) and bool((agent.options == -1).all())
    for _ in range(5):
        agent.observe(outside, torch.full((P,), -1.0, dtype=F64))
        assert bool((agent.decisions < 5).all())
    inside = HierarchicalAgent(make_bank(population=P), order=1, epsilon=1.0)
    inside.begin(obs(*[(0.7, 0.5, 0.5, 0.5)] * P))
    assert bool((inside.decisions == 5).any())  # sanity: available, it gets explored


def test_gestating_option_is_not_available():
    bank = make_bank()
    bank.set_status(bank.live(), OptionStatus.GESTATING)
    agent = make_agent(bank)
    prefer_option(agent, value=1e6)
    agent.begin(obs((0.7, 0.5, 0.5, 0.5)))
    assert agent.decisions.tolist() != [5]


def test_option_learns_only_inside_its_initiation_set():
    # slot 0: x > 0.5, slot 1: x < 0.5; the top level acts (primitives only are preferred).
    agent = make_agent(make_bank(slots=2, signs=(1.0, -1.0)))
    head = agent.bank.q_head
    agent.begin(obs((0.3, 0.5, 0.5, 0.5)))
    assert agent.options.tolist() == [-1]
    a = int(agent.action[0])
    before = head.weight.clone()
    agent.observe(obs((0.35, 0.5, 0.5, 0.5)), torch.tensor([-1.0], dtype=F64))
    moved = (head.weight != before).flatten(2).any(-1)[0]
    assert moved.tolist() == [False, True]
    # off-policy: the row of the primitive the top level took moved, in slot 1 only
    rows = (head.weight[0, 1] != before[0, 1]).any(-1).nonzero().flatten().tolist()
    assert rows == [a]
    # from x = 0.7 only slot 0 learns
    agent2 = make_agent(make_bank(slots=2, signs=(1.0, -1.0)))
    agent2.begin(obs((0.7, 0.5, 0.5, 0.5)))
    a = int(agent2.action[0])
    before = agent2.bank.q_head.weight.clone()
    agent2.observe(obs((0.72, 0.5, 0.5, 0.5)), torch.tensor([-1.0], dtype=F64))
    after = agent2.bank.q_head.weight
    moved = (after != before).flatten(2).any(-1)[0]
    assert moved.tolist() == [True, False]
    rows = (after[0, 0] != before[0, 0]).any(-1).nonzero().flatten().tolist()
    assert rows == [a]


def test_executing_option_stops_after_250_steps():
    agent = make_agent(make_bank())
    prefer_option(agent)
    s = obs((0.7, 0.5, 0.5, 0.5))  # in the set, never at the target region
    agent.begin(s)
    yes = torch.tensor([True])
    for step in range(1, 251):
        info = agent.transition(s, torch.tensor([-1.0], dtype=F64), NO, NO, yes)
        assert info["option"].tolist() == [0]
        assert info["decision_ended"].item() == (step == 250), step
    assert info["duration"].tolist() == [250]
    assert info["decision_return"].item() == -250.0


def test_option_interrupted_by_episode_end():
    agent = make_agent(make_bank())
    prefer_option(agent)
    agent.begin(obs((0.7, 0.5, 0.5, 0.5)))
    agent.observe(obs((0.7, 0.5, 0.5, 0.5)), torch.tensor([-1.0], dtype=F64))
    start = obs((0.6, 0.6, 0.5, 0.5))
    agent.observe_ends(obs((0.71, 0.5, 0.5, 0.5)), torch.tensor([-1.0], dtype=F64), NO,
                       torch.tensor([True]), torch.tensor([0]), start)
    # restarted: a fresh decision at the start state (the option again, it is preferred)
    assert agent.decisions.tolist() == [5] and int(agent.duration[0]) == 0
    assert torch.equal(agent.obs, start)


def test_option_reaches_region_in_the_real_physics():
    """From the start state an option that pushes down (-y) runs until the ball enters a region
    below it; the SMDP step credits it with the k steps and their summed reward."""
    from skillchain_torch.envs.pinball import observation

    region = RegionEvent(center=(0.2, 0.75), radius=0.03)
    bank = OptionBank(1, 1, FourierOptionQHead(1, 1, order=1),
                      InitiationClassifier(1, 1))  # untrained: available everywhere
    bank.status[:] = int(OptionStatus.LEARNED)
    bank.target_event[:] = 0
    bank.q_head.weight[0, 0, 3, 0] = 100.0  # greedy action: 3 (-y)
    agent = HierarchicalAgent(bank, order=1, alpha=0.01, epsilon=0.0, option_epsilon=0.0,
                              events=(region,))
    prefer_option(agent)
    env = PinballEnv("pinball_simple_single", batch_size=[1], seed=0)
    env.set_state(torch.tensor([[0.2, 0.9, 0.0, 0.0]], dtype=F64))
    s0 = observation(env.state)
    agent.begin(s0)
    assert agent.options.tolist() == [0]
    rewards, yes = [], torch.tensor([True])
    for _ in range(50):
        assert agent.actions.tolist() == [3]
        w = agent.q_head.weight.clone()
        obs1, reward, terminated, truncated = env.step_raw(agent.actions)
        rewards.append(reward.item())
        info = agent.transition(obs1, reward, terminated, truncated, yes)
        if info["decision_ended"].item():
            break
    k = len(rewards)
    assert region(obs1).item() and k > 5  # stopped on entering the region, not before
    assert info["duration"].item() == k and info["decision_return"].item() == sum(rewards)
    d_next = int(agent.decision[0])
    phi0, phi1 = agent.features(s0)[0], agent.features(obs1)[0]
    delta = (sum(rewards) + (w[0, d_next] * phi1).sum()) - (w[0, 5] * phi0).sum()
    expected = w.clone()
    expected[0, 5] += 0.01 * delta * phi0
    torch.testing.assert_close(agent.q_head.weight, expected, rtol=0, atol=1e-12)


def test_mlp_q_head_drops_in():
    P, K = 2, 1
    head = MLPOptionQHead(P, K, hidden=8, layers=1, seed=0)
    bank = make_bank(population=P, slots=K, q_head=head)
    agent = make_agent(bank, epsilon=0.0)
    prefer_option(agent)
    before = {k: v.clone() for k, v in head.state_dict().items()}
    s = obs(*[(0.7, 0.5, 0.5, 0.5)] * P)
    agent.begin(s)
    assert agent.options.tolist() == [0, 0]
    agent.observe(obs(*[(0.72, 0.5, 0.5, 0.5)] * P), torch.full((P,), -1.0, dtype=F64))
    after = head.state_dict()
    assert any(not torch.equal(before[k], after[k]) for k in before)
    assert agent.actions.shape == (P,)


@pytest.mark.parametrize(("top", "inner"), [(4, 3), (5, 3), (3, 3), (2, 3)])
def test_option_code_is_picked_from_the_top_level_features_bit_for_bit(top, inner):
    from skillchain_torch.agents.hierarchical import shared_fourier_columns
    from skillchain_torch.features import FourierBasis
    from skillchain_torch.options import FourierOptionQHead

    head = FourierOptionQHead(population=3, slots=2, order=inner)
    basis = FourierBasis(4, top)
    columns = shared_fourier_columns(basis, head)
    if top < inner:  # a coarser top level cannot supply the option features
        assert columns is None
        return
    obs = torch.rand(50, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(top))
    assert torch.equal(basis(obs)[:, columns], head.basis(obs))


@pytest.mark.parametrize("native", [False, None])
def test_episode_start_encodes_only_the_starting_rows(native):
    """A restart (observe_ends) gives the starting agent the features of its start state and a
    fresh decision, and leaves the other agents as a step without restarts would."""
    P = 3
    agents = [make_agent(make_bank(population=P, order=3), order=4, native=native)
              for _ in range(2)]  # fmt: skip
    start = obs((0.2, 0.3, 0.5, 0.5), (0.6, 0.7, 0.5, 0.5), (0.4, 0.8, 0.5, 0.5))
    later = obs((0.25, 0.3, 0.5, 0.5), (0.65, 0.7, 0.5, 0.5), (0.45, 0.8, 0.5, 0.5))
    restart = obs((0.8, 0.1, 0.5, 0.5))
    reward = torch.full((P,), -1.0, dtype=F64)
    ended = torch.tensor([False, True, False])
    for agent in agents:
        agent.begin(start)
    agents[0].observe_ends(later, reward, ended, torch.zeros_like(ended), torch.tensor([1]),
                           restart)  # fmt: skip
    agents[1].observe_ends(later, reward, ended, torch.zeros_like(ended),
                           torch.zeros(0, dtype=torch.int64), None)  # fmt: skip
    restarted, plain = agents
    expected = restarted.features(restart)[0]
    assert torch.equal(restarted.decision_phi[1], expected)  # the start state's features
    assert torch.equal(restarted.option_code[1], restarted._encode(restart)[1][0])
    assert torch.equal(restarted.obs[1], restart[0]) and int(restarted.duration[1]) == 0
    for name in ("obs", "decision_phi", "option_code", "decision", "option", "duration"):
        mine, theirs = getattr(restarted, name), getattr(plain, name)
        assert torch.equal(mine[[0, 2]], theirs[[0, 2]]), name  # the others untouched
    assert not torch.equal(restarted.decision_phi[1], plain.decision_phi[1])
