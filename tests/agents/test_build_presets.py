"""``SkillChainingAgent.build(preset=...)``: the presets' values reach the agent, keyword
arguments win over them, and an unknown name is refused in one line."""

from __future__ import annotations

import pytest

from skillchain_torch.agents import SkillChainingAgent
from skillchain_torch.discovery.readings import DEFAULT_READING, FIRST_READING
from skillchain_torch.presets import (
    DEFAULT,
    PAPER,
    PRESET_FIELDS,
    differences,
    instance_slots,
    preset_named,
)


def built_values(agent: SkillChainingAgent) -> dict:
    """The preset fields as the built agent holds them."""
    d, clf, head = agent.discovery, agent.bank.classifier.config, agent.bank.q_head.config
    return dict(
        epsilon=agent.epsilon, gamma=agent.gamma,
        scale_step_size=agent.update.step_size.dim() > 0,  # per-feature step sizes
        failure_bootstrap=agent.failure_bootstrap,
        completion_reward=agent.option_update.completion_reward,
        intra_option_primitives=agent.intra_option_primitives,
        intra_option_target=agent.intra_option_target,
        option_interruption=agent.interruption, end_outside_set=agent.end_outside_set,
        option_order=head["order"],
        option_alpha=head["alpha"], option_epsilon=agent.option_epsilon,
        max_option_steps=d.max_option_steps, policy_start=d.policy_start,
        value_start=d.value_start, value_bonus=d.value_bonus, slots=agent.bank.slots,
        gestation=d.gestation, max_branching=d.max_branching,
        convergence_threshold=d.convergence.threshold,
        convergence_episodes=d.convergence.episodes, overlap=d.overlap,
        subgoals="chained" if d.chaining else "random",
        degree=clf["degree"], lr=clf["lr"], sweeps=clf["sweeps"], distance=clf["distance"],
        capacity=clf["capacity"], balanced=clf["balanced"],
        keep_negatives=clf["keep_negatives"], store_failures=agent.bank.classifier.store_failures,
        constrain_nearest=agent.bank.classifier.constrain_nearest,
        initiation_bias=clf["initial_bias"],
        initiation_centered=clf["centered"],
        gestation_positives=d.reading.gestation_positives, initiation_start=d.reading.start,
        initiation_constrain=d.reading.constrain, one_class_fits=d.reading.one_class_fits,
    )


@pytest.mark.parametrize("preset", [DEFAULT, PAPER], ids=["default", "paper"])
def test_every_preset_value_reaches_the_agent(preset):
    agent = SkillChainingAgent.build(2, preset=preset.name, order=1)
    expected = {k: v for k, v in preset.to_dict().items() if k not in ("order", "alpha")}
    expected["slots"] = 12  # (the preset leaves it to the map: the first instance's)
    assert built_values(agent) == expected
    assert set(expected) | {"order", "alpha"} == set(PRESET_FIELDS)


def test_the_paper_preset_is_section_5_1():
    """The values the paper states (section 5.1), read onto the library's parameters."""
    agent = SkillChainingAgent.build(1, preset="paper")
    d = agent.discovery
    assert (d.gestation, d.max_branching, d.convergence.threshold, d.convergence.episodes) == (
        10, 3, 0.15, 2)
    assert (d.policy_start, d.value_start, d.reading) == ("zero", "max-sample", FIRST_READING)
    assert agent.bank.q_head.config["alpha"] == 0.0005 and agent.bank.q_head.config["order"] == 3
    assert agent.bank.classifier.config["distance"] == 0.1 and d.max_option_steps == 250
    assert (agent.epsilon, agent.option_epsilon, agent.gamma) == (0.01, 0.01, 1.0)
    assert agent.failure_bootstrap == "decision"
    assert (agent.order, agent.update.alpha) == (4, 0.001)  # the first instance's
    hard = SkillChainingAgent.build(1, preset="paper", map="pinball_hard_two_starts")
    assert (hard.order, hard.update.alpha) == (5, 0.0005)  # the second instance's


def test_the_default_preset_departs_in_the_documented_fields():
    assert SkillChainingAgent.build(1, order=1).discovery.reading == DEFAULT_READING
    assert set(differences(DEFAULT, PAPER)) == {
        "gestation", "gestation_positives", "initiation_start", "initiation_constrain",
        "policy_start", "value_start", "option_alpha", "failure_bootstrap", "end_outside_set"}


@pytest.mark.parametrize("preset", ["default", "paper"])
def test_the_slot_cap_is_the_maps_unless_given(preset):
    """48 option slots on the hard instance, 12 on the simple one and off Pinball (the
    full-size evidence is in ``instance_slots``'s docstring); an explicit value wins."""
    assert (DEFAULT.slots, PAPER.slots) == (None, None)
    hard = SkillChainingAgent.build(1, preset=preset, order=1, map="pinball_hard_two_starts")
    simple = SkillChainingAgent.build(1, preset=preset, order=1, map="pinball_simple_single")
    assert (hard.bank.slots, simple.bank.slots) == (48, 12)
    assert hard.num_decisions == 5 + 48  # the top level has a value per option
    given = SkillChainingAgent.build(1, preset=preset, order=1, map="pinball_hard_single",
                                     slots=7)  # fmt: skip
    assert given.bank.slots == 7
    assert [instance_slots(m) for m in ("pinball_hard_single", "pinball_box", None)] == [
        48, 12, 12]


def test_keyword_arguments_override_the_preset():
    agent = SkillChainingAgent.build(1, preset="paper", order=1, gestation=4, option_alpha=0.1,
                                     keep_negatives=False, interruption=True)
    assert (agent.discovery.gestation, agent.bank.q_head.config["alpha"]) == (4, 0.1)
    assert agent.bank.classifier.config["keep_negatives"] is False
    assert agent.interruption is True  # the constructor's own name wins too
    assert agent.discovery.policy_start == "zero"  # the rest stays the paper's


@pytest.mark.parametrize("call", [lambda: SkillChainingAgent.build(1, preset="papr"),
                                  lambda: preset_named(3)])
def test_an_unknown_preset_names_the_valid_ones(call):
    with pytest.raises(ValueError) as info:
        call()
    message = str(info.value)
    assert "\n" not in message and "valid presets: default, paper" in message, message


def test_replace_refuses_a_field_presets_do_not_have():
    with pytest.raises(TypeError, match="presets have no field gestaton"):
        PAPER.replace(gestaton=3)
