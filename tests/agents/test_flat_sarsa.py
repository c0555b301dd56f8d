"""FlatSarsaAgent against the library pieces driven by hand.

The torch path is those pieces, so it equals them bit for bit. The compiled path
(backends.sarsa, when built) takes the same decisions and its weights agree to rounding: its
dot products sum in their own order.
"""

import doctest
import importlib

import pytest
import torch

from skillchain_torch.agents import FlatSarsaAgent
from skillchain_torch.agents.flat_sarsa import BLOCK_DECISIONS
from skillchain_torch.backends import sarsa as native_sarsa
from skillchain_torch.features import FourierBasis
from skillchain_torch.modules import LinearQHead
from skillchain_torch.objectives import SarsaUpdate
from skillchain_torch.policies import epsilon_greedy
from skillchain_torch.rng import CounterRNG
from skillchain_torch.trainers import TrainConfig

F64 = torch.float64
KERNELS = [False, True] if native_sarsa.AVAILABLE else [False]


def _same_weights(native, got, expected):
    if native:  # own summation order: equal to rounding, and not bit for bit by design
        torch.testing.assert_close(got, expected, rtol=1e-10, atol=1e-10)
    else:
        assert torch.equal(got, expected)


def test_doctests():
    for name in ("skillchain_torch.agents.flat_sarsa", "skillchain_torch.trainers.config.registry",
                 "skillchain_torch.trainers.config.config", "skillchain_torch.backends.sarsa"):
        module = importlib.import_module(name)
        assert doctest.testmod(module, optionflags=doctest.ELLIPSIS).failed == 0


@pytest.mark.parametrize("native", KERNELS)
@pytest.mark.parametrize("order", [0, 1, 3, 4, 5])
@pytest.mark.parametrize("n", [1, 2, 3, 7, 100])
def test_featurize_equals_fourier_basis(order, n, native):
    """Both paths give FourierBasis's features bit for bit."""
    agent = FlatSarsaAgent(TrainConfig(runs=1, order=order), native=native)
    gen = torch.Generator().manual_seed(order * 1000 + n)
    # observations, including velocity parts outside [0, 1] after reflections
    obs = torch.rand(n, 4, dtype=F64, generator=gen) * 1.5 - 0.25
    assert torch.equal(agent.featurize(obs), FourierBasis(4, order)(obs))
    # strided input (the stepper returns views of a [n, 5] buffer)
    buf = torch.cat([obs, torch.zeros(n, 1, dtype=F64)], 1)
    assert torch.equal(agent.featurize(buf[:, :4]), FourierBasis(4, order)(obs))


@pytest.mark.skipif(not native_sarsa.AVAILABLE, reason="the compiled kernels were not built")
@pytest.mark.parametrize("epsilon", [0.0, 0.01, 0.5, 1.0])
def test_compiled_decisions_equal_epsilon_greedy(epsilon):
    """The kernel's choice (native_maths.h's rule) is policies.epsilon_greedy's, ties included."""
    gen = torch.Generator().manual_seed(1)
    n = 500
    # Q = w[i, d, 0] * 1: few distinct values, so many ties
    w = torch.randint(0, 3, (n, 5, 1), generator=gen).to(F64)
    u = torch.rand(n, 1, 2, dtype=F64, generator=gen)
    u[:7, 0, 1] = 1.0 - 2.0**-53  # the largest uniform
    expected = epsilon_greedy(w[:, :, 0], torch.ones(n, 5, dtype=torch.bool), epsilon, u[:, 0])
    ones, zero = torch.ones(n, 1, dtype=F64), torch.zeros((), dtype=F64)  # step 0: no update
    got = native_sarsa.sarsa_observe(w, ones, ones, torch.zeros(n, dtype=torch.int64),
                                     torch.zeros(n, dtype=F64), u, 0, epsilon, zero, None)
    assert torch.equal(got, expected)


def _reference_step(head, update, phi, a, r, next_phi, next_a, terminal):
    return update(head, phi, a, r, torch.ones_like(a), next_phi, next_a, terminal)


@pytest.mark.parametrize("native", KERNELS)
@pytest.mark.parametrize(("gamma", "scale", "P"),
                         [(1.0, False, 4), (0.9, False, 4), (1.0, True, 4), (1.0, False, 20)])
def test_observe_equals_library_pipeline(gamma, scale, P, native):
    """Run the agent's hot path and the library pieces side by side on random transitions."""
    cfg = TrainConfig(runs=P, seed=5, gamma=gamma, scale_step_size=scale, alpha=0.05,
                      epsilon=0.2)
    agent = FlatSarsaAgent(cfg, native=native)
    basis = FourierBasis(4, 4)
    head = LinearQHead(basis.num_features, 5, P)
    update = SarsaUpdate(0.05, gamma, basis.step_size_scale() if scale else None)
    rng = CounterRNG.from_seed(5, P)
    gen = torch.Generator().manual_seed(2)

    def ref_decide(phi):
        return epsilon_greedy(head(phi), torch.ones(P, 5, dtype=torch.bool), 0.2,
                              rng.uniform(2))

    obs = torch.rand(P, 4, dtype=F64, generator=gen)
    phi = basis(obs)
    a = ref_decide(phi)
    assert torch.equal(agent.begin(obs), a)
    for _ in range(BLOCK_DECISIONS + 3):  # crosses a uniform block refill
        obs = torch.rand(P, 4, dtype=F64, generator=gen)
        reward = torch.randint(-5, 0, (P,), generator=gen).to(F64) * 100
        next_phi = basis(obs)
        next_a = ref_decide(next_phi)
        _reference_step(head, update, phi, a, reward, next_phi, next_a,
                        torch.zeros(P, dtype=torch.bool))
        got = agent.observe(obs, reward)
        assert torch.equal(got, next_a)
        phi, a = next_phi, next_a
    agent.flush()
    _same_weights(native, agent.q_head.weight, head.weight)
    assert torch.equal(agent.rng.counter, rng.counter)


@pytest.mark.parametrize("native", KERNELS)
def test_terminal_and_truncated_updates_with_restarts(native):
    """observe_ends: terminated rows do not bootstrap and decide at their start state after
    the update; truncated rows bootstrap from s' and draw two more uniforms to restart."""
    P = 3
    cfg = TrainConfig(runs=P, seed=9, alpha=0.05, epsilon=0.3)
    agent = FlatSarsaAgent(cfg, native=native)
    basis = FourierBasis(4, 4)
    head = LinearQHead(basis.num_features, 5, P)
    update = SarsaUpdate(0.05, 1.0)
    rngs = [CounterRNG(torch.tensor([9 + p])) for p in range(P)]
    gen = torch.Generator().manual_seed(3)

    def decide_one(p, phi_p):
        q = (head.weight[p] * phi_p).sum(-1)[None]
        return epsilon_greedy(q, torch.ones(1, 5, dtype=torch.bool), 0.3, rngs[p].uniform(2))[0]

    obs = torch.rand(P, 4, dtype=F64, generator=gen)
    phi = basis(obs)
    a = torch.stack([decide_one(p, phi[p]) for p in range(P)])
    assert torch.equal(agent.begin(obs), a)
    for step in range(40):
        obs = torch.rand(P, 4, dtype=F64, generator=gen)
        reward = torch.full((P,), -5.0, dtype=F64)
        terminated = torch.tensor([step % 3 == 0, False, step % 5 == 1])
        truncated = torch.tensor([False, step % 4 == 2, False])
        reward[terminated] = 10000.0
        start = torch.rand(P, 4, dtype=F64, generator=gen)
        next_phi = basis(obs)
        # reference, one agent at a time in sequence
        next_a = torch.stack([decide_one(p, next_phi[p]) for p in range(P)])
        _reference_step(head, update, phi, a, reward, next_phi, next_a, terminated)
        ended = terminated | truncated
        phi_after, a_after = next_phi.clone(), next_a.clone()
        for p in range(P):
            if ended[p]:
                phi_after[p] = basis(start[p : p + 1])[0]
                if terminated[p]:  # the decision at s' is not made: give back its draws
                    rngs[p].counter -= 2
                a_after[p] = decide_one(p, phi_after[p])
        restart = ended.nonzero().flatten()
        got = agent.observe_ends(obs, reward, terminated, truncated, restart, start[restart])
        assert torch.equal(got, a_after), step
        phi, a = phi_after, a_after
    agent.flush()
    _same_weights(native, agent.q_head.weight, head.weight)
    assert agent.rng.counter.tolist() == [int(r.counter[0]) for r in rngs]


@pytest.mark.parametrize("native", KERNELS)
def test_compact_and_state_dict_round_trip(native):
    cfg = TrainConfig(runs=4, seed=1)
    agent = FlatSarsaAgent(cfg, native=native)
    obs = torch.rand(4, 4, dtype=F64, generator=torch.Generator().manual_seed(0))
    agent.begin(obs)
    agent.observe(obs, torch.full((4,), -1.0, dtype=F64))
    agent.compact(torch.tensor([True, False, True, False]))
    assert agent.index.tolist() == [0, 2]
    state = agent.state_dict()
    assert state["action"][1] == -1 and state["action"][3] == -1
    other = FlatSarsaAgent(cfg, native=native)
    other.load_state_dict(state)
    reward = torch.full((2,), -5.0, dtype=F64)
    assert torch.equal(agent.observe(obs[:2], reward), other.observe(obs[:2], reward))
    assert torch.equal(agent.state_dict()["q_head"]["weight"],
                       other.state_dict()["q_head"]["weight"])


def test_diverging_weights_raise_a_clear_error():
    from skillchain_torch.trainers import PopulationTrainer

    trainer = PopulationTrainer(TrainConfig(runs=2, alpha=1e3, episodes=1))
    with pytest.raises(FloatingPointError, match=r"agents \[0, 1\] have non-finite weights"):
        trainer.train()


@pytest.mark.skipif(not native_sarsa.AVAILABLE, reason="the compiled kernels were not built")
def test_state_of_the_other_kernel_is_refused():
    """The two kernels round differently, so a resumed run must keep its kernel."""
    cfg = TrainConfig(runs=2, seed=1)
    state = FlatSarsaAgent(cfg, native=True).state_dict()
    with pytest.raises(ValueError, match="saved by a native-kernel agent"):
        FlatSarsaAgent(cfg, native=False).load_state_dict(state)


@pytest.mark.skipif(not native_sarsa.AVAILABLE, reason="the compiled kernels were not built")
def test_native_q_values_agree_with_linear_q_head():
    gen = torch.Generator().manual_seed(4)
    head = LinearQHead(625, 5, 7)
    head.weight = torch.randn(7, 5, 625, dtype=F64, generator=gen)
    phi = torch.rand(3, 625, dtype=F64, generator=gen)
    rows = torch.tensor([6, 0, 3])
    expected = head.weight[rows].mul(phi[:, None]).sum(-1)
    torch.testing.assert_close(native_sarsa.linear_q(head.weight, phi, rows), expected,
                               rtol=1e-13, atol=1e-12)
    # and not by accident: a row's value does not depend on the other rows asked for
    assert torch.equal(native_sarsa.linear_q(head.weight, phi[1:2], rows[1:2]),
                       native_sarsa.linear_q(head.weight, phi, rows)[1:2])


@pytest.mark.skipif(not native_sarsa.AVAILABLE, reason="the compiled kernels were not built")
def test_resuming_with_the_other_kernel_names_the_checkpoint(tmp_path):
    from skillchain_torch.trainers import PopulationTrainer
    from skillchain_torch.trainers.outputs.checkpoint import load_checkpoint

    cfg = TrainConfig(runs=2, episodes=2, max_episode_steps=50, checkpoint_every=1)
    path = PopulationTrainer(cfg, out_dir=tmp_path, native=False).train().checkpoint_path()
    with pytest.raises(ValueError, match=r"ckpt_000002\.pt: this state was saved by a torch"):
        load_checkpoint(path, PopulationTrainer(cfg, out_dir=tmp_path))


@pytest.mark.skipif(not native_sarsa.AVAILABLE, reason="the compiled kernels were not built")
def test_native_agent_reads_strided_rewards_correctly():
    """The Python-float stepper hands rewards as a column of an [n, 5] block."""
    cfg = TrainConfig(runs=3, seed=2, alpha=0.05)
    a, b = FlatSarsaAgent(cfg, native=True), FlatSarsaAgent(cfg, native=True)
    obs = torch.rand(3, 4, dtype=F64, generator=torch.Generator().manual_seed(1))
    a.begin(obs)
    b.begin(obs)
    block = torch.zeros(3, 5, dtype=F64)
    block[:, 4] = torch.tensor([-5.0, -1.0, -5.0])
    assert torch.equal(a.observe(obs, block[:, 4]), b.observe(obs, block[:, 4].clone()))
    a.flush()
    b.flush()
    assert torch.equal(a.q_head.weight, b.q_head.weight)
    assert a.q_head.weight.abs().sum() > 0
