"""The neural pieces learn (issue 31): on a crafted chain whose return is known, the MLP top-level
head (SMDP Sarsa loss, Huber on scaled errors, a target network, replay) and the MLP option head
(intra-option Q-learning on scaled errors) approach it at returns of order 10^4; the MLP
initiation classifier learns a region no linear model separates; and a skill-chaining agent
built from all three runs, chains, checkpoints and resumes."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torch import nn

from skillchain_torch.agents import SkillChainingAgent
from skillchain_torch.interfaces import InitiationSet, ValueHead, missing_methods
from skillchain_torch.modules import MLPQHead
from skillchain_torch.objectives import (
    IntraOptionQLearning,
    OptionReplay,
    ReplayTD,
    SMDPSarsaLoss,
)
from skillchain_torch.options import MLPInitiationClassifier, MLPOptionQHead, OptionBank
from skillchain_torch.trainers import PopulationTrainer, TrainConfig

F64 = torch.float64
N, P, GOAL = 10, 2, 10_000.0  # a chain of N states; the last pays GOAL
# Moving right from state i: -1 per step, GOAL - 1 on entering the last state.
TRUE = torch.tensor([GOAL - (N - 1 - i) for i in range(N - 1)], dtype=F64)


def chain_obs(i: torch.Tensor) -> torch.Tensor:
    obs = torch.full((i.shape[0], 4), 0.5, dtype=F64)
    obs[:, 0] = i.to(F64) / (N - 1)
    return obs


def test_mlp_top_level_head_approaches_the_chains_return():
    head = MLPQHead(num_features=4, num_decisions=3, population=P, hidden=32, value_scale=1000.0)
    assert missing_methods(head, ValueHead) == []
    loss = SMDPSarsaLoss(head, loss_function="smooth_l1", value_scale=1000.0, delay_value=True)
    learner = ReplayTD(loss, torch.optim.Adam(head.parameters(), lr=3e-3), batch_size=32,
                       target_update=100, capacity=5000)  # fmt: skip
    g = torch.Generator().manual_seed(0)
    states = chain_obs(torch.arange(N - 1))[:, None, :].expand(-1, P, -1)
    before = (head(states)[..., 0] - TRUE[:, None]).abs().max()
    for _ in range(1500):
        i = torch.randint(0, N - 1, (P,), generator=g)
        end = i + 1 == N - 1
        td = TensorDict(
            phi=chain_obs(i), decision=torch.zeros(P, dtype=torch.long),
            decision_return=torch.where(end, GOAL - 1.0, -1.0).to(F64),
            duration=torch.ones(P, dtype=torch.long), next_value=torch.zeros(P, dtype=F64),
            terminated=end, active=torch.ones(P, dtype=torch.bool), next_phi=chain_obs(i + 1),
            next_decision=torch.zeros(P, dtype=torch.long),
            next_available=torch.ones(P, 3, dtype=torch.bool), batch_size=[P],
        )  # fmt: skip
        learner(td)
    error = (head(states)[..., 0] - TRUE[:, None]).abs().max()
    assert before > 9_000 and error < 0.05 * GOAL, (before, error)  # within 5% of 10^4
    assert learner.updates > 1000


def test_mlp_option_head_approaches_the_chains_return_and_stays_finite():
    """The option's target is the chain's end: r + C there (C = 10^4). Before the errors were
    scaled, this head was NaN after 78 updates at q_scale = 1000."""
    head = MLPOptionQHead(P, 1, hidden=32, lr=0.05, q_scale=1000.0)
    update = IntraOptionQLearning(gamma=1.0, completion_reward=GOAL)
    g = torch.Generator().manual_seed(1)
    inside = torch.ones(P, 1, dtype=torch.bool)
    for _ in range(1500):
        i = torch.randint(0, N - 1, (P,), generator=g)
        update(head, chain_obs(i), torch.zeros(P, dtype=torch.long), -torch.ones(P, dtype=F64),
               chain_obs(i + 1), torch.zeros(P, dtype=torch.bool), inside,
               (i + 1 == N - 1)[:, None])  # fmt: skip
    q = torch.stack([head(chain_obs(torch.full((P,), k)))[:, 0, 0] for k in range(N - 1)])
    assert bool(torch.isfinite(q).all())
    assert (q - TRUE[:, None]).abs().max() < 0.05 * GOAL


def test_mlp_option_head_huber_bounds_each_step():
    """One update on a TD error of 10^6 moves Q by about lr x (gradient size), not 10^6 x."""
    head = MLPOptionQHead(1, 1, hidden=8, lr=0.01)
    obs = torch.full((1, 4), 0.5, dtype=F64)
    head.td_update(obs, torch.tensor([0]), torch.full((1, 1), 1e6, dtype=F64),
                   torch.ones(1, 1, dtype=torch.bool))  # fmt: skip
    assert 0 < head(obs)[0, 0, 0] < 100.0


def test_mlp_initiation_classifier_learns_a_region_no_line_separates():
    clf = MLPInitiationClassifier(population=2, slots=2, capacity=400, hidden=16, sweeps=200)
    assert isinstance(clf, InitiationSet) and not clf.builtin_model()
    g = torch.Generator().manual_seed(3)
    x = torch.rand(400, 4, dtype=F64, generator=g)
    disc = ((x[:, :2] - 0.5) ** 2).sum(-1) < 0.08  # agent 0 slot 1: a disc
    band = (x[:, 1] > 0.3) & (x[:, 1] < 0.6)  # agent 1 slot 0: a band
    clf.add_examples(0, 1, x, disc)
    clf.add_examples(1, 0, x, band)
    clf.fit()
    test = torch.rand(1000, 4, dtype=F64, generator=g)
    accuracy_disc = (clf.contains_points(0, 1, test)
                     == (((test[:, :2] - 0.5) ** 2).sum(-1) < 0.08)).double().mean()  # fmt: skip
    accuracy_band = (clf.contains_points(1, 0, test)
                     == ((test[:, 1] > 0.3) & (test[:, 1] < 0.6))).double().mean()  # fmt: skip
    assert accuracy_disc > 0.9 and accuracy_band > 0.9, (accuracy_disc, accuracy_band)
    assert bool(clf.contains_points(0, 0, test).all())  # untrained slots hold everything


def test_mlp_classifier_reset_slot_starts_afresh_and_agents_are_their_own():
    a = MLPInitiationClassifier(population=3, slots=2, capacity=8, seed=5)
    b = MLPInitiationClassifier(population=1, slots=2, capacity=8, seed=torch.tensor([6]))
    assert torch.equal(a.layer_weights[0][1], b.layer_weights[0][0])  # agent 1 = seed 6
    first = a.layer_weights[0][0, 1].clone()
    a.reset_slots(torch.tensor([[False, True], [False, False], [False, False]]))
    assert not torch.equal(first, a.layer_weights[0][0, 1])  # a new generation, new weights
    assert torch.equal(a.layer_biases[-1][0, 1], torch.zeros(1, dtype=F64))


def test_option_replay_approaches_the_chains_return_and_forgets_a_slots_predecessor():
    head = MLPOptionQHead(P, 2, hidden=32, lr=0.05, q_scale=1000.0)
    head.replay = OptionReplay(batch_size=16, train_every=1, target_update=50, seed=0)
    update = IntraOptionQLearning(gamma=1.0, completion_reward=GOAL)
    g = torch.Generator().manual_seed(2)
    only_first = torch.tensor([[True, False]] * P)  # slot 1 never in its set: learns nothing
    for _ in range(1500):
        i = torch.randint(0, N - 1, (P,), generator=g)
        update(head, chain_obs(i), torch.zeros(P, dtype=torch.long), -torch.ones(P, dtype=F64),
               chain_obs(i + 1), torch.zeros(P, dtype=torch.bool), only_first,
               (i + 1 == N - 1)[:, None].expand(-1, 2))  # fmt: skip
    q = torch.stack([head(chain_obs(torch.full((P,), k)))[:, :, 0] for k in range(N - 1)])
    assert (q[..., 0] - TRUE[:, None]).abs().max() < 0.05 * GOAL
    assert float(q[..., 1].abs().max()) == 0.0  # untouched: masked out of every sample
    assert int(head.replay.updates.min()) > 1000  # every agent learned, each on its own count
    # A new option takes slot 0: the stored transitions are its predecessor's, so a replayed
    # step leaves the fresh slot where it starts (Q = 0).
    head.reset_slots(torch.tensor([[True, False]] * P))
    head.replay._learn(head, 1.0, GOAL)
    assert float(head(chain_obs(torch.zeros(P)))[:, 0].abs().max()) == 0.0


def neural_agent(population=2, slots=4, seed=0):
    option_head = MLPOptionQHead(population, slots, hidden=16, lr=0.05, seed=seed)
    option_head.replay = OptionReplay(batch_size=16, train_every=2, target_update=50, seed=seed)
    bank = OptionBank(population, slots, option_head,
                      MLPInitiationClassifier(population, slots, capacity=100, hidden=8,
                                              sweeps=20, seed=seed))  # fmt: skip
    head = MLPQHead(4, 5 + slots, population, hidden=32, seed=seed)
    loss = SMDPSarsaLoss(head, loss_function="smooth_l1", value_scale=1000.0, delay_value=True)
    learner = ReplayTD(loss, torch.optim.Adam(head.parameters(), lr=1e-3), batch_size=16,
                       target_update=100, train_every=4, seed=seed)  # fmt: skip
    return SkillChainingAgent(bank, q_head=head, features=nn.Identity(), top_learner=learner,
                              gestation=1, policy_start="zero", value_start="max-sample",
                              seed=seed)  # fmt: skip


@pytest.mark.slow
def test_a_neural_skill_chaining_agent_trains_chains_and_resumes(tmp_path):
    cfg = TrainConfig(agent="skill-chaining", map="pinball_box", runs=2, episodes=4,
                      max_episode_steps=600, seed=0, checkpoint_every=2)  # fmt: skip
    agent = neural_agent()
    assert not agent.native and not agent.closed_form
    whole = PopulationTrainer(cfg, out_dir=tmp_path / "whole", agent=agent).train()
    assert agent.top_learner.updates > 0 and agent.bank.q_head.replay.stored > 0
    assert bool((agent.bank.status > 0).any())  # discovery created options
    assert all(torch.isfinite(p).all() for p in agent.q_head.parameters())
    # Interrupted after 2 episodes and resumed: the same returns.
    part = PopulationTrainer(cfg, out_dir=tmp_path / "part", agent=neural_agent())
    part.train(max_agent_steps=1)
    while part.episodes_done.min() < 2:
        part.train(max_agent_steps=part.agent_steps + 1)
    state = part.state_dict()
    resumed = PopulationTrainer(cfg, out_dir=tmp_path / "resumed", agent=neural_agent())
    resumed.load_state_dict(state)
    resumed.train()
    assert resumed.returns.tolist() == whole.returns.tolist()


def test_the_config_names_the_pieces_and_refuses_unknown_ones():
    cfg = TrainConfig(agent="skill-chaining", preset="paper", map="pinball_box", runs=2,
                      episodes=1, max_episode_steps=30, top_head="mlp", option_head="mlp",
                      initiation="mlp")  # fmt: skip
    trainer = PopulationTrainer(cfg)
    agent = trainer.agent
    assert (type(agent.q_head), type(agent.bank.q_head), type(agent.bank.classifier)) == (
        MLPQHead, MLPOptionQHead, MLPInitiationClassifier)
    trainer.train()
    with pytest.raises(ValueError, match=r"^top_head must be one of fourier, mlp, got 'rnn'$"):
        TrainConfig(agent="skill-chaining", preset="paper", top_head="rnn").validate()
    TrainConfig(agent="skill-chaining", top_head="mlp", option_head="mlp").validate()
    with pytest.raises(ValueError, match="'top-level-shifted' needs Fourier heads.*"
                                         "--policy-start top-level$"):  # fmt: skip
        TrainConfig(agent="skill-chaining", top_head="mlp",
                    policy_start="top-level-shifted").validate()


def test_register_piece_adds_a_name_the_config_accepts():
    from skillchain_torch.agents import pieces

    class Wider(MLPInitiationClassifier):
        pass

    pieces.register_piece("initiation", "wider",
                          lambda clf: Wider(population=clf.population, slots=clf.slots,
                                            capacity=16, hidden=4))  # fmt: skip
    try:
        agent = SkillChainingAgent.build(2, preset="paper", initiation="wider", order=1)
        assert type(agent.bank.classifier) is Wider
        TrainConfig(agent="skill-chaining", initiation="wider").validate(memory=False)
        with pytest.raises(ValueError, match="^initiation must be one of logistic, mlp, wider"):
            TrainConfig(agent="skill-chaining", initiation="nope").validate(memory=False)
    finally:
        del pieces.INITIATIONS["wider"]
    with pytest.raises(ValueError, match="--initiation must be one of logistic, mlp"):
        SkillChainingAgent.build(2, initiation="wider", order=1)


def test_max_branching_zero_is_the_same_agent_without_options():
    """--max-branching 0: no event is ever listed, so no option is created: the flat baseline
    of any top-level head (the neural one included)."""
    cfg = TrainConfig(agent="skill-chaining", preset="paper", map="pinball_box", runs=2,
                      episodes=3, max_episode_steps=200, max_branching=0, gestation=1,
                      top_head="mlp")  # fmt: skip
    trainer = PopulationTrainer(cfg).train()
    assert not bool(trainer.agent.bank.live().any())
    assert trainer.agent.top_learner.updates > 0


@pytest.mark.cuda
@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device on this machine")
def test_neural_skill_chaining_runs_on_cuda():
    cfg = TrainConfig(agent="skill-chaining", preset="paper", map="pinball_box", runs=4,
                      episodes=2, max_episode_steps=300, gestation=1, device="cuda",
                      top_head="mlp", option_head="mlp", initiation="mlp")  # fmt: skip
    trainer = PopulationTrainer(cfg).train()
    agent = trainer.agent
    assert next(agent.q_head.parameters()).device.type == "cuda"
    assert agent.bank.classifier.examples.device.type == "cuda"
    assert agent.top_learner.updates > 0 and not agent.native


def test_a_joining_options_value_reaches_the_target_network_at_once():
    """Discovery's set_values writes the online head; the replay learner copies the target at
    its next call instead of bootstrapping from the slot's stale value until a scheduled copy."""
    head = MLPQHead(2, 3, P, hidden=8, value_scale=10.0)
    loss = SMDPSarsaLoss(head, loss_function="smooth_l1", value_scale=10.0, delay_value=True)
    learner = ReplayTD(loss, torch.optim.Adam(head.parameters(), lr=1e-2), batch_size=4,
                       target_update=10_000)  # fmt: skip
    phi = torch.zeros(P, 2, dtype=F64)
    yes, no = torch.ones(P, dtype=torch.bool), torch.zeros(P, dtype=torch.bool)
    td = TensorDict(phi=phi, decision=torch.tensor([0, 1]), decision_return=torch.ones(P),
                    duration=torch.ones(P, dtype=torch.long), next_value=torch.zeros(P),
                    terminated=no, active=yes, next_phi=phi, next_decision=torch.tensor([2, 2]),
                    batch_size=[P]).to(F64)  # fmt: skip
    for _ in range(8):
        learner(td)
    head.set_values(torch.tensor([[False, False, True]] * P), torch.full((P, 3), 77.0, dtype=F64))
    learner(td)
    with loss.target_value_head_params.to_module(head):
        assert head(phi)[:, 2].tolist() == [77.0, 77.0]
