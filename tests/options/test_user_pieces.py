"""A researcher's own pieces are honoured on every path: membership, fitting, convergence,
images, save/load, and the choice of backend (issue 29).

Each test plugs a piece of the user's own class in through the public API and checks that the
library's answer is the piece's answer, on the default path (the compiled one where it is built)
and on the torch path.
"""

from __future__ import annotations

import doctest

import pytest
import torch
from torch import nn

import skillchain_torch.backends.select as select
import skillchain_torch.interfaces as interfaces
import skillchain_torch.options.initiation_fit as initiation_fit
import skillchain_torch.options.io as options_io
from skillchain_torch.agents import HierarchicalAgent, SkillChainingAgent
from skillchain_torch.backends.initiation import AVAILABLE as NATIVE_BUILT
from skillchain_torch.interfaces import InitiationSet, OptionHead, ValueHead, missing_methods
from skillchain_torch.invariant import rowwise_dot
from skillchain_torch.modules import LinearQHead
from skillchain_torch.options import (
    FourierOptionQHead,
    InitiationClassifier,
    OptionBank,
    OptionQHead,
    register_classifier,
    register_q_head,
)
from skillchain_torch.trainers.outputs.option_monitor import initiation_density

F64 = torch.float64


@register_classifier
class LeftOfLine(InitiationClassifier):
    """A user's model: an ``nn.Linear`` on the raw observation, one per slot (not the
    built-in polynomial weights, which stay at zero)."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.net = nn.Linear(4, self.population * self.slots, dtype=F64)
        with torch.no_grad():  # start at "inside iff x < 0.5" for every slot
            self.net.weight.zero_()
            self.net.weight[:, 0] = -4.0
            self.net.bias.fill_(2.0)

    def logit(self, obs):
        z = self.net(obs)  # [P, *B, P * K]
        z = z.reshape(*z.shape[:-1], self.population, self.slots)
        # agent p's states meet agent p's slots only
        index = torch.arange(self.population)
        return z.movedim(-2, 1)[index, index]  # [P, *B, K]


def user_bank(population=2, slots=2, **kwargs):
    clf = LeftOfLine(population=population, slots=slots, capacity=64, **kwargs)
    return OptionBank(population, slots, FourierOptionQHead(population, slots, order=1), clf)


def states(xs):
    return torch.tensor([[x, 0.5, 0.5, 0.5] for x in xs], dtype=F64)


def test_user_logit_decides_membership_on_the_default_agent_path():
    bank = user_bank()
    bank.classifier.trained.fill_(True)  # fitted: the logit decides
    agent = SkillChainingAgent(bank, order=1)
    assert agent.native is NATIVE_BUILT  # the step may be compiled: the classifier is not
    assert bank.classifier.native is False
    inside, outside = states([0.2, 0.2]), states([0.8, 0.8])
    assert bool(agent.membership(inside).all()) and not bool(agent.membership(outside).any())
    # the built-in polynomial weights are zero: had they been used, every logit would be 0
    assert float(bank.classifier.weight.abs().sum()) == 0.0


def test_asking_for_the_compiled_classifier_with_a_user_model_names_it():
    bank = user_bank()
    with pytest.raises(ValueError, match="the initiation classifier is LeftOfLine, not the "
                                         "built-in InitiationClassifier"):
        bank.classifier.set_native(True)
    if NATIVE_BUILT:
        with pytest.raises(ValueError, match="initiation classifier is LeftOfLine"):
            HierarchicalAgent(bank, order=1, native=True)
    assert HierarchicalAgent(user_bank(), order=1, native=False).bank.classifier.native is False


@pytest.mark.parametrize("balanced", [False, True])
def test_fit_trains_the_user_model_and_not_the_builtin_weights(balanced):
    clf = LeftOfLine(population=1, slots=2, capacity=64, lr=2.0, balanced=balanced)
    # slot 0 learns "right of x = 0.5", the opposite of its starting model
    x = torch.rand(64, 4, dtype=F64, generator=torch.Generator().manual_seed(1))
    clf.add_examples(0, 0, x, x[:, 0] > 0.5)
    before = {k: v.clone() for k, v in clf.net.state_dict().items()}
    fitted = clf.fit()
    assert fitted.tolist() == [[True, False]]
    assert not torch.equal(before["weight"], clf.net.weight)
    assert float(clf.weight.abs().sum()) == 0.0 and float(clf.bias.abs().sum()) == 0.0
    member = torch.stack([clf.contains(row[None])[0, 0] for row in x])
    assert float((member == (x[:, 0] > 0.5)).double().mean()) > 0.9
    assert clf.trained.tolist() == [[True, False]] and clf.sweeps_done[0, 0] == clf.sweeps


def test_convergence_measure_follows_the_user_model():
    clf = LeftOfLine(population=1, slots=2, capacity=64)
    start = clf.snapshot()
    assert start.shape == (1, 2, initiation_fit.PROBE_POINTS)
    assert clf.weight_change(start).tolist() == [[0.0, 0.0]]
    x = torch.rand(32, 4, dtype=F64, generator=torch.Generator().manual_seed(2))
    clf.add_examples(0, 1, x, x[:, 0] > 0.5)
    clf.fit()
    change = clf.weight_change(start)
    assert float(change[0, 1]) > 0.15 and float(change[0, 0]) < float(change[0, 1])


def test_images_use_the_user_model():
    clf = LeftOfLine(population=2, slots=1, capacity=8)
    clf.trained.fill_(True)
    points = states([0.1, 0.3, 0.7, 0.9])
    assert clf.contains_points(1, 0, points).tolist() == [True, True, False, False]
    density = initiation_density(clf, agent=1, slot=0, resolution=10)
    assert 0.35 < float(density.mean()) < 0.65  # about half the board is left of x = 0.5


def test_constraint_and_untrained_rule_stay_with_a_user_model():
    clf = LeftOfLine(population=1, slots=1, capacity=8)
    far = states([0.1])
    assert clf.contains(states([0.9])).tolist() == [[True]]  # untrained: everywhere
    clf.add_examples(0, 0, states([0.3]), torch.tensor([True]))
    clf.trained.fill_(True)
    clf.constrain(torch.ones(1, 1, dtype=torch.bool))
    assert clf.contains(far).tolist() == [[False]]  # inside the logit, too far from 0.3
    assert clf.contains_points(0, 0, far).tolist() == [False]


def test_a_saved_bank_reloads_the_user_classifier(tmp_path):
    bank = user_bank()
    with torch.no_grad():
        bank.classifier.net.bias.fill_(-3.0)
    bank.classifier.trained.fill_(True)
    bank.save(tmp_path / "bank.pt")
    loaded = OptionBank.load(tmp_path / "bank.pt")
    assert type(loaded.classifier) is LeftOfLine
    obs = states([0.2, 0.6])
    assert torch.equal(loaded.classifier.contains(obs), bank.classifier.contains(obs))
    assert torch.equal(loaded.classifier.net.bias, bank.classifier.net.bias)


def test_an_unregistered_part_is_a_one_line_error(tmp_path):
    class Unknown(InitiationClassifier):
        pass

    bank = OptionBank(1, 1, FourierOptionQHead(1, 1, order=1),
                      Unknown(population=1, slots=1, capacity=4))  # fmt: skip
    bank.save(tmp_path / "bank.pt")
    with pytest.raises(ValueError, match=r"bank\.pt: initiation classifier class 'Unknown' is "
                                         r"not registered .*register_classifier\(Unknown\)"):
        OptionBank.load(tmp_path / "bank.pt")


def test_gradient_fit_equals_the_closed_form_fit_on_the_logistic_model():
    """The built-in closed-form sweeps are SGD on the same loss: a subclass that re-implements
    the logistic model with its own parameters, fitted by autograd, lands on the same weights
    to rounding."""

    class Autograd(InitiationClassifier):
        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            self.w = nn.Parameter(torch.zeros_like(self.weight))
            self.b = nn.Parameter(torch.zeros_like(self.bias))

        def logit(self, obs):
            phi = self.phi(obs)
            between = (1,) * (phi.ndim - 2)
            w = self.w.view(self.population, *between, self.slots, -1)
            return (w * phi[..., None, :]).sum(-1) + self.b.view(self.population, *between,
                                                                  self.slots)  # fmt: skip

    for balanced in (False, True):
        kwargs = dict(population=2, slots=2, capacity=32, sweeps=30, balanced=balanced)
        builtin, mine = InitiationClassifier(**kwargs), Autograd(**kwargs)
        builtin.set_native(False)
        x = torch.rand(40, 4, dtype=F64, generator=torch.Generator().manual_seed(3))
        agents, slots = torch.arange(40) % 2, (torch.arange(40) // 2) % 2
        labels = (x[:, 0] + x[:, 1]) > 1.0
        for clf in (builtin, mine):
            clf.add_examples(agents, slots, x, labels)
            clf.fit()
        torch.testing.assert_close(mine.w.detach(), builtin.weight, rtol=0, atol=1e-9)
        torch.testing.assert_close(mine.b.detach(), builtin.bias, rtol=0, atol=1e-9)


def test_builtin_logit_takes_batches_of_states_per_agent():
    clf = InitiationClassifier(population=3, slots=2, capacity=4)
    with torch.no_grad():
        clf.weight.normal_(generator=torch.Generator().manual_seed(4))
    obs = torch.rand(3, 5, 4, dtype=F64)
    batched = clf.logit(obs)
    assert batched.shape == (3, 5, 2)
    for i in range(5):  # the one-state-per-agent logit, bit for bit
        assert torch.equal(batched[:, i], clf.logit(obs[:, i]))
    assert torch.equal(batched[1, 2], rowwise_dot(clf.weight[1], clf.phi(obs[1, 2])) + clf.bias[1])


class OwnHead(FourierOptionQHead):
    """A user's option head: the Fourier head with an optimistic offset on every value."""

    def forward(self, obs):
        return super().forward(obs) + 1.0


def test_a_subclassed_option_head_takes_the_torch_path_and_is_named():
    bank = OptionBank(1, 2, OwnHead(1, 2, order=1), InitiationClassifier(1, 2, capacity=4))
    agent = HierarchicalAgent(bank, order=1)
    assert agent.native is False and agent._code_columns is None
    if NATIVE_BUILT:
        with pytest.raises(ValueError, match="the option head is OwnHead, not the built-in "
                                             "FourierOptionQHead"):
            HierarchicalAgent(bank, order=1, native=True)


def test_an_option_head_must_declare_its_slot_tensors():
    class NoSlots(OptionQHead):
        def forward(self, obs):
            return obs

        def td_update(self, obs, action, target, mask):
            return target

        def reset_slots(self, mask):
            pass

        def select_agents(self, index, seeds=None):
            return self

    with pytest.raises(TypeError, match="slot_tensors"):
        NoSlots()


def test_a_registered_option_head_reloads(tmp_path):
    register_q_head(OwnHead)
    bank = OptionBank(1, 2, OwnHead(1, 2, order=1), InitiationClassifier(1, 2, capacity=4))
    bank.save(tmp_path / "bank.pt")
    assert type(OptionBank.load(tmp_path / "bank.pt").q_head) is OwnHead


def test_builtins_satisfy_the_interfaces():
    clf = InitiationClassifier(population=1, slots=1, capacity=4)
    head = LinearQHead(num_features=3, num_decisions=6, population=1)
    assert isinstance(clf, InitiationSet) and missing_methods(clf, InitiationSet) == []
    assert isinstance(head, ValueHead) and missing_methods(head, ValueHead) == []
    assert isinstance(FourierOptionQHead(1, 1, order=1), OptionHead)
    assert isinstance(LeftOfLine(population=1, slots=1, capacity=4), InitiationSet)


@pytest.mark.parametrize("module", [interfaces, select, initiation_fit, options_io])
def test_docstring_examples(module):
    assert doctest.testmod(module, raise_on_error=True).attempted > 0


def test_a_set_that_discovery_cannot_fit_is_refused_before_the_run():
    """Overriding ``logit`` on the built-in weights (which have no gradient) used to build, run
    and then fail at the first fit, mid-run; now skill-chaining discovery refuses it in one line
    as it is built. The same class with a trainable parameter is accepted, and a fixed set that
    is only used (a bank of given options: never fitted) is not refused."""
    from skillchain_torch.agents import HierarchicalAgent, SkillChainingAgent

    class Wrapped(InitiationClassifier):
        def logit(self, obs):
            return super().logit(obs)

    def bank(cls):
        return OptionBank(2, 2, FourierOptionQHead(2, 2, order=1),
                          cls(population=2, slots=2, capacity=8))  # fmt: skip

    with pytest.raises(ValueError, match="Wrapped overrides logit or phi but has no parameter"):
        SkillChainingAgent(bank(Wrapped), order=1)
    HierarchicalAgent(bank(Wrapped), order=1)  # sets used as given: nothing to fit

    class Trainable(Wrapped):
        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            self.weight.requires_grad_()

    assert isinstance(SkillChainingAgent(bank(Trainable), order=1).bank.classifier, Trainable)
