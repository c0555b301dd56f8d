"""HierarchicalAgent in hand-built situations (issue 4, "Monitoring and proof")."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from skillchain_torch.agents import HierarchicalAgent, make_region_option
from skillchain_torch.collectors import HierarchicalCollector
from skillchain_torch.envs.pinball import PinballEnv
from skillchain_torch.options import (
    FourierOptionQHead,
    InitiationClassifier,
    MLPOptionQHead,
    OptionBank,
    OptionStatus,
    RegionEvent,
)

F64 = torch.float64
TARGET = (0.9, 0.2)
REGION = RegionEvent(center=TARGET, radius=0.05, name="target region")


def obs(*rows) -> torch.Tensor:
    return torch.tensor([list(r) for r in rows], dtype=F64)


def half_plane(classifier: InitiationClassifier, slot: int, sign: float) -> None:
    """Slot ``slot``'s initiation set: ``x > 0.5`` (sign +1) or ``x < 0.5`` (sign -1)."""
    with torch.no_grad():
        classifier.weight[:, slot] = 0.0
        classifier.weight[:, slot, 1] = sign  # feature 1 is x (PolynomialFeatures order)
        classifier.bias[:, slot] = -0.5 * sign
        classifier.trained[:, slot] = True


def make_bank(population=1, slots=1, signs=(1.0,), order=1, q_head=None, seed=0):
    q_head = q_head or FourierOptionQHead(population, slots, order=order)
    bank = OptionBank(population, slots, q_head,
                      InitiationClassifier(population, slots, seed=seed))
    for k, sign in enumerate(signs):
        half_plane(bank.classifier, k, sign)
    bank.status[:] = int(OptionStatus.LEARNED)
    bank.target_event[:] = 0
    return bank


def make_agent(bank, **kwargs) -> HierarchicalAgent:
    kwargs = {"order": 1, "alpha": 0.01, "epsilon": 0.0, "option_epsilon": 0.0,
              "events": (REGION,), **kwargs}
    return HierarchicalAgent(bank, **kwargs)


def prefer_option(agent: HierarchicalAgent, slot: int = 0, value: float = 100.0) -> None:
    """Make Q(s, option) = ``value`` everywhere (feature 0 is the constant cosine)."""
    agent.q_head.weight[:, 5 + slot, 0] = value


NO = torch.tensor([False])


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


def run_collector(population, seed, steps, bank_seed_offset=0):
    bank = make_bank(population=population, slots=2, signs=(1.0, -1.0), order=2,
                     seed=seed + bank_seed_offset)
    agent = HierarchicalAgent(bank, order=2, alpha=0.001, epsilon=0.2, seed=seed,
                              events=(REGION,))
    env = PinballEnv("pinball_simple_single", batch_size=[population], seed=seed,
                     max_episode_steps=40)
    collector = HierarchicalCollector(env, agent, frames_per_batch=steps * population)
    return agent, collector.rollout()


def test_population_equals_single_runs():
    S, P, steps = 11, 3, 120
    pop, batch = run_collector(P, S, steps)
    assert bool((batch["option"] >= 0).any())  # options were executed
    assert bool(batch["next", "done"].any())  # and episodes restarted
    for p in (0, 2):
        alone, single = run_collector(1, S + p, steps)
        assert torch.equal(batch["decision"][:, p], single["decision"][:, 0])
        assert torch.equal(batch["action"][:, p], single["action"][:, 0])
        assert torch.equal(pop.q_head.weight[p], alone.q_head.weight[0])
        assert torch.equal(pop.bank.q_head.weight[p], alone.bank.q_head.weight[0])
        assert torch.equal(pop.rng.counter[p], alone.rng.counter[0])


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


def test_state_dict_round_trip():
    agent = make_agent(make_bank())
    prefer_option(agent)
    agent.begin(obs((0.7, 0.5, 0.5, 0.5)))
    agent.observe(obs((0.72, 0.5, 0.5, 0.5)), torch.tensor([-1.0], dtype=F64))
    state = agent.state_dict()
    other = make_agent(make_bank())
    other.load_state_dict(state)
    for a, b in ((agent, other),):
        assert torch.equal(a.q_head.weight, b.q_head.weight)
        assert torch.equal(a.bank.q_head.weight, b.bank.q_head.weight)
        assert torch.equal(a.rng.counter, b.rng.counter)
    s = obs((0.74, 0.5, 0.5, 0.5))
    r = torch.tensor([-1.0], dtype=F64)
    assert torch.equal(agent.observe(s, r), other.observe(s, r))
    assert torch.equal(agent.q_head.weight, other.q_head.weight)


def test_compact_keeps_rows():
    agent = make_agent(make_bank(population=3))
    agent.begin(obs(*[(0.3, 0.5, 0.5, 0.5)] * 3))
    agent.compact(torch.tensor([True, False, True]))
    assert agent.index.tolist() == [0, 2]
    assert agent.observe(obs(*[(0.31, 0.5, 0.5, 0.5)] * 2),
                         torch.full((2,), -1.0, dtype=F64)).shape == (2,)


def test_region_option_file_round_trip(tmp_path):
    bank = make_region_option(examples=200, pretrain_steps=30, batch=20)
    path = tmp_path / "region.pt"
    bank.save(path)
    loaded = OptionBank.from_agent(path, 0, 2, seeds=torch.tensor([5, 6]))
    assert loaded.status.tolist() == [[int(OptionStatus.LEARNED)]] * 2
    near = obs((0.85, 0.25, 0.5, 0.5), (0.2, 0.9, 0.5, 0.5))
    assert loaded.available(near)[:, 0].tolist() == [True, False]
    agent = HierarchicalAgent(loaded, seed=5)
    agent.q_head.weight[:, 5, 0] = 1e4
    agent.begin(near)
    assert agent.options.tolist() == [0, -1]


def test_given_options_agent(tmp_path):
    from skillchain_torch.trainers.config import TrainConfig
    from skillchain_torch.trainers.given_options import GivenOptionsAgent

    path = tmp_path / "region.pt"
    make_region_option(examples=200, pretrain_steps=20, batch=20).save(path)

    @dataclasses.dataclass(frozen=True)
    class Config(TrainConfig):
        options: str | None = None

    agent = GivenOptionsAgent(Config(agent="flat", runs=2, seed=3, options=str(path)))
    assert agent.q_head.weight.shape == (2, 6, 625)
    assert agent.bank.status.tolist() == [[3], [3]]
    assert agent.rng.seeds.tolist() == [3, 4]
    with pytest.raises(ValueError, match="options"):
        GivenOptionsAgent(TrainConfig(runs=1))


def test_population_trainer_drives_given_options(tmp_path, monkeypatch):
    from skillchain_torch.trainers import agents as registry
    from skillchain_torch.trainers.config import TrainConfig
    from skillchain_torch.trainers.population import PopulationTrainer

    monkeypatch.setitem(registry.AGENTS, "given-options", "given_options:GivenOptionsAgent")
    bank = OptionBank.build(1, slots=2, order=2)  # untrained classifiers: available everywhere
    bank.status[0, 0] = int(OptionStatus.LEARNED)
    bank.target_event[0, 0] = 0  # the goal
    path = tmp_path / "everywhere.pt"
    bank.save(path)

    @dataclasses.dataclass(frozen=True)
    class Config(TrainConfig):
        options: str | None = None

    def train(runs, seed):
        cfg = Config(agent="given-options", runs=runs, seed=seed, episodes=2, order=2,
                     epsilon=0.2, max_episode_steps=60, options=str(path))
        trainer = PopulationTrainer(cfg).train()
        return trainer

    pop, alone = train(3, 7), train(1, 8)
    assert pop.agent.bank.status[:, 1].tolist() == [0, 0, 0]  # the empty slot stays empty
    assert pop.finished and pop.lengths.shape == (3, 2)
    assert (pop.returns[1] == alone.returns[0]).all()
    assert torch.equal(pop.weights[1], alone.weights[0])
    assert torch.equal(pop.agent.bank.q_head.weight[1], alone.agent.bank.q_head.weight[0])
    assert bool((pop.agent.bank.q_head.weight[:, 0] != 0).any())  # the option learned
    assert bool((pop.weights[:, 5] != 0).all(-1).any())  # and was chosen by the top level


def test_trainer_resume_matches_uninterrupted(tmp_path, monkeypatch):
    import io

    from skillchain_torch.trainers import agents as registry
    from skillchain_torch.trainers.config import TrainConfig
    from skillchain_torch.trainers.population import PopulationTrainer

    monkeypatch.setitem(registry.AGENTS, "given-options", "given_options:GivenOptionsAgent")
    bank = OptionBank.build(1, slots=1, order=2)
    bank.status[0, 0] = int(OptionStatus.LEARNED)
    bank.target_event[0, 0] = 0
    path = tmp_path / "everywhere.pt"
    bank.save(path)

    @dataclasses.dataclass(frozen=True)
    class Config(TrainConfig):
        options: str | None = None

    cfg = Config(agent="given-options", runs=2, seed=1, episodes=3, order=2, epsilon=0.2,
                 max_episode_steps=40, options=str(path))
    full = PopulationTrainer(cfg).train()
    first = PopulationTrainer(cfg).train(max_agent_steps=130)  # stops mid-episode
    buffer = io.BytesIO()
    torch.save(first.state_dict(), buffer)
    buffer.seek(0)
    resumed = PopulationTrainer(cfg)
    resumed.load_state_dict(torch.load(buffer, weights_only=True))
    resumed.train()
    assert (resumed.returns == full.returns).all()
    assert torch.equal(resumed.weights, full.weights)
    assert torch.equal(resumed.agent.bank.q_head.weight, full.agent.bank.q_head.weight)


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


@pytest.mark.parametrize("native", [False, True])
@pytest.mark.parametrize("rule", ["decision", "primitives"])
def test_timed_out_option_bootstraps_by_failure_bootstrap(rule, native):
    """A timeout's SMDP target: Q(s', d') (Sarsa) or the best primitive at s' ("primitives"),
    while a success (the option's target reached) bootstraps on d' under both rules."""
    if native and not HierarchicalAgent(make_bank(), order=1, native=None).native:
        pytest.skip("compiled agent kernels not built")
    agent = make_agent(make_bank(), failure_bootstrap=rule, max_option_steps=3, native=native)
    prefer_option(agent, value=100.0)  # the option is re-chosen at s' (d' = 5)
    agent.q_head.weight[:, 2, 0] = 7.0  # the best primitive: Q(s, 2) = 7 everywhere
    s = obs((0.7, 0.5, 0.5, 0.5))  # in the set, never at the target region
    agent.begin(s)
    yes = torch.tensor([True])
    for _ in range(2):
        agent.transition(s, torch.tensor([-1.0], dtype=F64), NO, NO, yes)
    w = agent.q_head.weight.clone()
    info = agent.transition(s, torch.tensor([-1.0], dtype=F64), NO, NO, yes)
    assert info["decision_ended"].tolist() == [True] and info["duration"].tolist() == [3]
    assert agent.decisions.tolist() == [5]  # d' is the option again
    q_sa = (w[0, 5] * agent.features(s)[0]).sum().item()
    boot = 100.0 if rule == "decision" else 7.0
    assert info["smdp_delta"].item() == pytest.approx(-3.0 + boot - q_sa, rel=1e-12)
    # a success bootstraps on d' whatever the rule
    agent2 = make_agent(make_bank(), failure_bootstrap=rule, native=native)
    prefer_option(agent2, value=100.0)
    agent2.q_head.weight[:, 2, 0] = 7.0
    agent2.begin(s)
    goal = obs((0.9, 0.2, 0.5, 0.5))  # in the set and at the target region
    w = agent2.q_head.weight.clone()
    info = agent2.transition(goal, torch.tensor([-1.0], dtype=F64), NO, NO, yes)
    q_sa = (w[0, 5] * agent2.features(s)[0]).sum().item()
    d_next = int(agent2.decision[0])
    q_next = (w[0, d_next] * agent2.features(goal)[0]).sum().item()
    assert d_next == 5
    assert info["smdp_delta"].item() == pytest.approx(-1.0 + q_next - q_sa, rel=1e-12)


def test_failure_bootstrap_is_checked():
    with pytest.raises(ValueError, match="failure_bootstrap must be one of"):
        make_agent(make_bank(), failure_bootstrap="optimistic")


@pytest.mark.parametrize("native", [False, True])
@pytest.mark.parametrize("intra", [False, True])
def test_intra_option_primitives_learn_the_options_steps(intra, native):
    """With ``intra_option_primitives`` each step an option takes moves the top level's
    Q(s, a) of that primitive toward r + max over the decisions available at s' (the option
    where s' is in its set, the primitives only where it is not, nothing at a termination);
    without it the primitives' values learn nothing while the option runs."""
    if native and not HierarchicalAgent(make_bank(), order=1, native=None).native:
        pytest.skip("compiled agent kernels not built")
    agent = make_agent(make_bank(), intra_option_primitives=intra, native=native)
    prefer_option(agent, value=100.0)
    agent.q_head.weight[:, 2, 0] = 7.0  # the best primitive: 7 everywhere
    agent.q_head.weight[:, 1, 1] = -3.0  # and one that varies with s
    s = obs((0.7, 0.5, 0.5, 0.5))
    agent.begin(s)
    yes = torch.tensor([True])
    # s' in the option's set (the option is available there), outside it, then a termination
    path = [(obs((0.6, 0.4, 0.5, 0.5)), NO, 100.0), (obs((0.3, 0.4, 0.5, 0.5)), NO, None),
            (obs((0.35, 0.4, 0.5, 0.5)), yes, 0.0)]
    for s1, terminated, best in path:
        assert agent.options.tolist() == [0]  # the option runs (its target is elsewhere)
        w, a, phi = agent.q_head.weight.clone(), int(agent.action[0]), agent.features(s)[0]
        agent.transition(s1, torch.tensor([-1.0], dtype=F64), terminated, NO, yes)
        if not intra:
            assert torch.equal(agent.q_head.weight[:, :5], w[:, :5])
            s = s1
            continue
        if best is None:  # outside the set: the best primitive at s1
            best = max(float(w[0, d] @ agent.features(s1)[0]) for d in range(5))
        delta = -1.0 + best - float(w[0, a] @ phi)
        expected = w.clone()
        expected[0, a] += 0.01 * delta * phi
        torch.testing.assert_close(agent.q_head.weight[:, :5], expected[:, :5], rtol=0,
                                   atol=1e-12)  # (the termination also ends the decision)
        s = s1


def test_intra_option_primitives_state_survives_a_checkpoint():
    """phi(s) of the current state is rebuilt from s on load: a resumed agent takes the same
    updates as one that never stopped."""
    bank_a, bank_b = make_bank(), make_bank()
    a, b = (make_agent(bank, intra_option_primitives=True, epsilon=0.2, option_epsilon=0.2)
            for bank in (bank_a, bank_b))  # fmt: skip
    for agent in (a, b):
        prefer_option(agent, value=100.0)
    g = torch.Generator().manual_seed(0)
    start = obs((0.7, 0.5, 0.5, 0.5))
    a.begin(start)
    yes = torch.tensor([True])
    steps = [torch.rand(1, 4, dtype=F64, generator=g) for _ in range(12)]
    for s1 in steps[:6]:
        a.transition(s1, torch.tensor([-1.0], dtype=F64), NO, NO, yes)
    b.load_state_dict(a.state_dict())
    for s1 in steps[6:]:
        for agent in (a, b):
            agent.transition(s1, torch.tensor([-1.0], dtype=F64), NO, NO, yes)
    assert torch.equal(a.q_head.weight, b.q_head.weight)


@pytest.mark.parametrize("native", [False, True])
@pytest.mark.parametrize("interruption", [False, True])
def test_interruption_stops_an_option_where_it_is_no_longer_greedy(interruption, native):
    """Q(s, o) = 10 + 20 cos(pi x) falls as x grows, the best primitive is worth 12: the
    option is chosen at x = 0.2 and, with interruption, stops at x = 0.48 (11.26 < 12, still in
    its set x < 0.5), where the SMDP update closes it on the primitive d' = 2; without, it runs
    on."""
    if native and not HierarchicalAgent(make_bank(), order=1, native=None).native:
        pytest.skip("compiled agent kernels not built")
    agent = make_agent(make_bank(signs=(-1.0,)), interruption=interruption, native=native)
    agent.q_head.weight[:, 5, 0] = 10.0
    agent.q_head.weight[:, 5, 8] = 20.0  # feature 8 is cos(pi x) (coefficients (1, 0, 0, 0))
    agent.q_head.weight[:, 2, 0] = 12.0
    s0 = obs((0.2, 0.5, 0.5, 0.5))
    assert float(agent.features(s0)[0, 8]) == pytest.approx(0.809017, abs=1e-6)  # cos(0.2 pi)
    agent.begin(s0)
    assert agent.decisions.tolist() == [5]
    yes = torch.tensor([True])
    w = agent.q_head.weight.clone()
    for x in (0.3, 0.45):
        info = agent.transition(obs((x, 0.5, 0.5, 0.5)), torch.tensor([-1.0], dtype=F64), NO,
                                NO, yes)  # fmt: skip
        assert info["decision_ended"].tolist() == [False] and agent.options.tolist() == [0]
    s3 = obs((0.48, 0.5, 0.5, 0.5))
    info = agent.transition(s3, torch.tensor([-1.0], dtype=F64), NO, NO, yes)
    if not interruption:
        assert info["decision_ended"].tolist() == [False] and agent.options.tolist() == [0]
        assert torch.equal(agent.q_head.weight, w)
        return
    assert info["decision_ended"].tolist() == [True] and info["duration"].tolist() == [3]
    assert agent.decisions.tolist() == [2] and agent.options.tolist() == [-1]
    q_s0 = float(w[0, 5] @ agent.features(s0)[0])
    assert info["smdp_delta"].item() == pytest.approx(-3.0 + 12.0 - q_s0, rel=1e-12)
