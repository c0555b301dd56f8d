"""The hierarchical agent's compiled step (backends/hierarchical.py) against the library pieces.

Each kernel takes the same decisions from the same uniforms as the pieces it mirrors, and its
values and weights agree to rounding (its sums run in their own order). The agents built on
it keep the reproducibility contract on their own: agent p alone equals agent p in a
population, bit for bit, with either kind of kernel (tests/trainers/test_skill_chaining_run.py).
"""

import doctest

import numpy as np
import pytest
import torch

from skillchain_torch.agents import HierarchicalAgent, SkillChainingAgent
from skillchain_torch.agents.step_state import STEP_FIELDS, StepState
from skillchain_torch.backends import hierarchical as native_hierarchical
from skillchain_torch.modules import LinearQHead
from skillchain_torch.options import FourierOptionQHead, MLPOptionQHead, OptionBank, OptionStatus
from skillchain_torch.policies import epsilon_greedy
from skillchain_torch.trainers import PopulationTrainer, TrainConfig

F64 = torch.float64
needs_native = pytest.mark.skipif(
    not native_hierarchical.AVAILABLE,
    reason="the compiled agent step was not built (no C compiler at install time)")
KERNELS = [False, True] if native_hierarchical.AVAILABLE else [False]


def gen(seed):
    return torch.Generator().manual_seed(seed)


def close(got, expected):
    torch.testing.assert_close(got, expected, rtol=1e-10, atol=1e-10)


def test_built_in_ci():
    import os

    if os.environ.get("CI"):
        assert native_hierarchical.AVAILABLE, "skillchain_torch.backends._hierarchical failed"


def test_doctest():
    from skillchain_torch.agents import hierarchical, step_state

    for module in (native_hierarchical, step_state, hierarchical):
        assert doctest.testmod(module).failed == 0, module.__name__


@needs_native
@pytest.mark.parametrize("epsilon", [0.0, 0.3, 1.0])
@pytest.mark.parametrize("integer", [True, False])
def test_choose_equals_forward_mask_and_epsilon_greedy(epsilon, integer):
    P, D, F = 300, 9, 16
    g = gen(int(epsilon * 10) + integer)
    head = LinearQHead(F, D, P)
    if integer:  # exact small sums: many real ties among the values
        head.weight.copy_(torch.randint(-1, 2, (P, D, F), generator=g).to(F64))
        phi = torch.randint(0, 2, (P, F), generator=g).to(F64)
    else:
        head.weight.copy_(torch.randn(P, D, F, dtype=F64, generator=g))
        phi = torch.randn(P, F, dtype=F64, generator=g)
    available = torch.rand(P, D, generator=g) < 0.5
    available[:, :5] = True  # primitives always
    rows = torch.rand(P, generator=g) < 0.7
    u = torch.rand(P, 4, dtype=F64, generator=g)
    q_ref = head.forward_mask(phi, available & rows[:, None], dense=5)
    d_ref = epsilon_greedy(q_ref, available, epsilon, u[:, :2], check=False)
    q, d = native_hierarchical.choose(head.weight, phi, available, rows, 5, u[:, :2], epsilon)
    close(q, q_ref)
    assert torch.equal(d, d_ref)
    if integer:
        assert torch.equal(q, q_ref)


@needs_native
@pytest.mark.parametrize("epsilon", [0.0, 0.5])
def test_act_equals_option_values_and_epsilon_greedy(epsilon):
    P, K, Fo = 200, 3, 16
    g = gen(7)
    head = FourierOptionQHead(P, K, order=1)
    head.weight.copy_(torch.randint(-1, 2, head.weight.shape, generator=g).to(F64))
    code = torch.randint(0, 2, (P, Fo), generator=g).to(F64)
    rows = torch.rand(P, generator=g) < 0.8
    decision = torch.randint(0, 5 + K, (P,), generator=g)
    option = torch.where(decision >= 5, decision - 5, -1)
    u = torch.rand(P, 4, dtype=F64, generator=g)
    before = torch.randint(0, 5, (P,), generator=g)
    # the torch path of HierarchicalAgent._act
    expected = decision.clamp(max=4)
    index = (rows & (option >= 0)).nonzero()[:, 0]
    q = head.slot_values_rows(code, option, index)
    by_option = epsilon_greedy(q, torch.ones_like(q, dtype=torch.bool), epsilon, u[index, 2:])
    expected = torch.where(rows, expected.index_put((index,), by_option), before)
    got = native_hierarchical.act(head.weight, code, rows, decision, option, u[:, 2:], epsilon,
                                  before.clone())
    assert torch.equal(got, expected)


def half_plane_bank(P, seed):
    """Two LEARNED options with trained half-plane sets (x > 0.5, x < 0.5) and random heads,
    so the top level can choose them and they act, learn and end."""
    g = gen(seed)
    bank = OptionBank.build(P, 2, order=2, alpha=0.01, seed=seed)
    bank.q_head.weight.copy_(torch.randn(bank.q_head.weight.shape, dtype=F64, generator=g))
    clf = bank.classifier
    with torch.no_grad():
        for k, sign in enumerate((1.0, -1.0)):
            clf.weight[:, k, 1] = sign  # feature 1 is x
            clf.bias[:, k] = -0.5 * sign
    clf.trained[:] = True
    bank.status[:] = int(OptionStatus.LEARNED)
    bank.target_event[:] = 0
    return bank


@needs_native
@pytest.mark.parametrize(("gamma", "scaled", "intra", "interruption", "failure", "leave"), [
    (1.0, False, False, False, "decision", "off"), (0.9, False, False, False, "decision", "off"),
    (0.95, True, False, False, "decision", "off"), (1.0, False, True, False, "primitives", "off"),
    (0.9, True, True, True, "primitives", "off"), (1.0, False, False, True, "decision", "off"),
    (1.0, False, "primitives", False, "decision", "off"),
    (1.0, False, False, False, "primitives", "always"),
    (0.9, True, True, True, "decision", "always"),
    (1.0, False, False, False, "primitives", "learned")])
def test_compiled_transition_agrees_with_the_torch_path(gamma, scaled, intra, interruption,
                                                        failure, leave):
    """Random transitions with terminations, truncations and rows not stepped: the same
    decisions and actions, TD errors and weights equal to rounding, with the discounted and
    per-feature step sizes too."""
    P, steps = 30, 120
    agents = [HierarchicalAgent(half_plane_bank(P, seed=1), order=2, alpha=0.01, gamma=gamma,
                                epsilon=0.3, option_epsilon=0.3, seed=7,
                                scale_step_size=scaled, completion_reward=50.0,
                                intra_option_primitives=bool(intra),
                                intra_option_target=("primitives" if intra == "primitives"
                                                     else "decisions"),
                                interruption=interruption, end_outside_set=leave,
                                failure_bootstrap=failure, native=native)
              for native in (False, True)]  # fmt: skip
    for agent in agents:  # (one option still learning its set: only the other ends outside)
        agent.bank.status[:, 1] = int(OptionStatus.LEARNING if leave == "learned"
                                      else OptionStatus.LEARNED)  # fmt: skip
    g = gen(2)
    start = torch.rand(P, 4, dtype=F64, generator=g)
    assert torch.equal(agents[0].begin(start), agents[1].begin(start))
    seen_options = torch.zeros((), dtype=torch.bool)
    for _ in range(steps):
        next_obs = torch.rand(P, 4, dtype=F64, generator=g)
        reward = torch.randn(P, dtype=F64, generator=g)
        terminated = torch.rand(P, generator=g) < 0.05
        truncated = torch.rand(P, generator=g) < 0.05
        stepped = torch.rand(P, generator=g) < 0.9
        expected, got = (a.transition(next_obs, reward, terminated, truncated, stepped)
                         for a in agents)  # fmt: skip
        for key in ("decision_ended", "duration", "decision", "option", "reached"):
            assert torch.equal(got[key], expected[key]), key
        for key in ("decision_return", "smdp_delta", "option_delta"):
            close(got[key], expected[key])
        for name in ("decision", "option", "action", "duration", "contains"):
            assert torch.equal(getattr(agents[1], name), getattr(agents[0], name)), name
        close(agents[1].decision_return, agents[0].decision_return)
        seen_options |= (expected["option"] >= 0).any()
    close(agents[1].q_head.weight, agents[0].q_head.weight)
    close(agents[1].bank.q_head.weight, agents[0].bank.q_head.weight)
    assert bool(seen_options)  # options ran


@needs_native
def test_compiled_step_takes_and_returns_the_declared_state():
    """The backend reads the agent's StepState and returns the state at s' (fresh tensors
    but for the three arrays it updates in place); the agent's fields are that state's."""
    P = 4
    agent = HierarchicalAgent(half_plane_bank(P, seed=1), order=2, seed=3, native=True,
                              intra_option_primitives=True)  # fmt: skip
    start = torch.rand(P, 4, dtype=F64, generator=gen(0))
    agent.begin(start)
    before = agent.step_state
    kept = {name: getattr(before, name).clone() for name in STEP_FIELDS}
    next_obs = torch.rand(P, 4, dtype=F64, generator=gen(1))
    agent.observe(next_obs, torch.full((P,), -1.0, dtype=F64))
    after = agent.step_state
    assert type(after) is StepState and after is not before
    assert torch.equal(after.obs, next_obs) and torch.equal(before.obs, kept["obs"])
    in_place = {"option_code", "decision_phi", "state_phi"}
    for name in STEP_FIELDS:
        assert (getattr(after, name) is getattr(before, name)) == (name in in_place), name
        assert getattr(agent, name) is getattr(after, name)
    # a decision either ended (a fresh one starts at 0) or went on one step longer
    assert bool(((after.duration == 0) | (after.duration == kept["duration"] + 1)).all())


@needs_native
def test_the_compiled_transition_writes_no_attribute_of_the_agent():
    """The backend computes and returns; the agent adopts (issue 51: no object writes
    another's attributes). Writing any attribute during the kernel's call fails here."""
    P = 4
    agent = HierarchicalAgent(half_plane_bank(P, seed=1), order=2, seed=3, native=True)
    agent.begin(torch.rand(P, 4, dtype=F64, generator=gen(0)))
    kernel_transition, inside = agent.kernel.transition, []

    class Guarded(type(agent)):  # the same agent, refusing writes while the kernel runs
        def __setattr__(self, name, value):
            if inside:
                raise AssertionError(f"the compiled step wrote agent.{name}")
            super().__setattr__(name, value)

    def transition(*args):
        inside.append(True)
        try:
            return kernel_transition(*args)
        finally:
            inside.clear()

    agent.__class__ = Guarded
    agent.kernel = type("Kernel", (), {"transition": staticmethod(transition)})()
    before = agent.step_state
    agent.observe(torch.rand(P, 4, dtype=F64, generator=gen(1)), torch.full((P,), -1.0,
                                                                            dtype=F64))
    assert agent.step_state is not before  # the agent adopted the returned state


# ---------------------------------------------------------------------------- agents
BOX = dict(agent="skill-chaining", map="pinball_box", max_episode_steps=300, slots=4)


def box_trainer(runs, seed, native, episodes=6):
    config = TrainConfig(runs=runs, seed=seed, episodes=episodes, **BOX)
    trainer = PopulationTrainer(config, native=native)
    bank = OptionBank.build(runs, config.slots, seed=seed)
    trainer.agent = SkillChainingAgent(bank, order=4, alpha=0.001, seed=seed, gestation=2,
                                       native=native)  # fmt: skip
    return trainer


@needs_native
def test_skill_chaining_run_takes_the_same_course_with_either_kernel():
    by_kind = {native: box_trainer(2, seed=3, native=native).train() for native in KERNELS}
    a, b = by_kind[False], by_kind[True]
    assert a.agent.native is False and b.agent.native is True
    assert b.agent.bank.classifier.native is True
    assert bool(b.agent.bank.live().any())  # options were created, joined and executed
    assert int(b.agent.bank.classifier.sweeps_done.sum()) > 0
    assert np.array_equal(a.returns, b.returns)
    assert torch.equal(a.agent.bank.status, b.agent.bank.status)
    close(b.agent.q_head.weight, a.agent.q_head.weight)
    close(b.agent.bank.q_head.weight, a.agent.bank.q_head.weight)
    close(b.agent.bank.classifier.weight, a.agent.bank.classifier.weight)


@needs_native
def test_state_from_the_other_kernel_is_refused():
    torch_agent = SkillChainingAgent.build(1, slots=2, order=1, native=False)
    native_agent = SkillChainingAgent.build(1, slots=2, order=1, native=True)
    with pytest.raises(ValueError, match="torch-kernel agent.*native kernels"):
        native_agent.load_state_dict(torch_agent.state_dict())
    native_agent.load_state_dict(SkillChainingAgent.build(1, slots=2, order=1).state_dict())


def test_native_true_names_what_is_missing():
    bank = OptionBank(1, 1, MLPOptionQHead(1, 1, hidden=4, layers=1),
                      OptionBank.build(1, 1).classifier)
    with pytest.raises(ValueError, match="the option head is MLPOptionQHead, not the built-in"):
        HierarchicalAgent(bank, order=1, native=True)
    agent = HierarchicalAgent(bank, order=1)  # the default falls back to torch
    assert agent.native is False and agent.bank.classifier.native is False


@needs_native
def test_leaving_float64_turns_the_compiled_path_off():
    """C reads raw float64 CPU memory: an agent moved out of it falls back to torch."""
    agent = SkillChainingAgent.build(1, slots=2, order=1)
    assert agent.native is True
    agent.to(torch.float32)
    assert agent.native is False and agent.bank.classifier.native is False


@needs_native
def test_more_decisions_than_the_kernel_holds_take_the_torch_path():
    """The kernel's rows live on the stack (MAX_CHOICES): a bank past them runs in torch, and
    asking for C there names the limit instead of failing mid-run."""
    limit = native_hierarchical.MAX_CHOICES
    assert SkillChainingAgent.build(1, slots=limit - 5, order=1).native is True
    assert SkillChainingAgent.build(1, slots=limit - 4, order=1).native is False
    with pytest.raises(ValueError, match=f"at most {limit} decisions"):
        SkillChainingAgent.build(1, slots=limit - 4, order=1, native=True)
