"""The agents of a neural population are independent runs (issue 31): each stores, samples and
learns from its own replay memory on its own schedule, so what another agent does (stores,
discovers an option, finishes early) never changes its run. Before per-agent replay a
population step was stored when any agent's decision ended and one set of indices was drawn
for all agents, and these tests failed."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict

from skillchain_torch.modules import MLPQHead
from skillchain_torch.objectives import IntraOptionQLearning, OptionReplay, ReplayTD, SMDPSarsaLoss
from skillchain_torch.options import MLPInitiationClassifier, MLPOptionQHead, OptionBank
from skillchain_torch.trainers import PopulationTrainer, TrainConfig

F64 = torch.float64


def _top_run(other_active: float, other_writes: bool, steps: int = 120):
    """Agent 0 sees the same stream in every call; agent 1's activity depends on the args."""
    head = MLPQHead(2, 3, 2, hidden=8, value_scale=10.0, seed=3)
    loss = SMDPSarsaLoss(head, loss_function="smooth_l1", value_scale=10.0, delay_value=True)
    learner = ReplayTD(loss, torch.optim.Adam(head.parameters(), lr=1e-2), batch_size=4,
                       target_update=7, train_every=2, seed=11)  # fmt: skip
    g0, g1 = torch.Generator().manual_seed(0), torch.Generator().manual_seed(1)
    for t in range(steps):
        phi = torch.stack([torch.rand(2, generator=g0, dtype=F64),
                           torch.rand(2, generator=g1, dtype=F64)])  # fmt: skip
        active = torch.tensor([t % 3 != 0, bool(torch.rand(1, generator=g1) < other_active)])
        td = TensorDict(phi=phi, decision=torch.tensor([t % 3, 1]),
                        decision_return=torch.tensor([float(t % 5), 2.0], dtype=F64),
                        duration=torch.ones(2, dtype=torch.long),
                        next_value=torch.zeros(2, dtype=F64),
                        terminated=torch.tensor([t % 7 == 0, False]), active=active,
                        next_phi=phi.flip(0), next_decision=torch.tensor([0, 2]),
                        batch_size=[2])  # fmt: skip
        learner(td)
        if other_writes and t == 40:  # discovery sets a joining option's value for agent 1 only
            head.set_values(torch.tensor([[False, False, False], [False, False, True]]),
                            torch.full((2, 3), 50.0, dtype=F64))  # fmt: skip
    return [p[0].detach().clone() for p in head.parameters()]


def _check_agent_zero_is_its_own(run, others, steps):
    """Agent 0's weights are the same whatever agent 1 does, and differ with one step less of
    its own (so the comparison could fail)."""
    base = run(*others[0], steps=steps)
    for other in others[1:]:
        assert all(torch.equal(a, b) for a, b in zip(base, run(*other, steps=steps))), other
    assert any(not torch.equal(a, b) for a, b in zip(base, run(*others[0], steps=steps - 1)))


def test_the_top_levels_replay_keeps_each_agents_learning_its_own():
    _check_agent_zero_is_its_own(_top_run, [(0.5, False), (0.0, False), (1.0, True), (0.1, True)],
                                 steps=120)  # fmt: skip


def _option_run(other_rate: float, reset_other: bool, steps: int = 150):
    head = MLPOptionQHead(2, 2, hidden=8, lr=0.05, q_scale=100.0, seed=5)
    head.replay = OptionReplay(batch_size=4, train_every=2, target_update=5, seed=9)
    update = IntraOptionQLearning(gamma=1.0, completion_reward=100.0)
    g0, g1 = torch.Generator().manual_seed(0), torch.Generator().manual_seed(1)
    for t in range(steps):
        obs = torch.stack([torch.rand(4, generator=g0, dtype=F64),
                           torch.rand(4, generator=g1, dtype=F64)])  # fmt: skip
        learn = torch.tensor([[t % 2 == 0, True],
                              [bool(torch.rand(1, generator=g1) < other_rate), False]])
        reached = torch.tensor([[t % 5 == 0, False], [False, t % 3 == 0]])
        update(head, obs, torch.tensor([t % 5, 1]), -torch.ones(2, dtype=F64), obs.flip(0),
               torch.zeros(2, dtype=torch.bool), learn, reached)  # fmt: skip
        if reset_other and t == 60:  # a new option takes agent 1's slot 0
            head.reset_slots(torch.tensor([[False, False], [True, False]]))
    return [p[0].clone() for p in head.params.values()]


def test_the_option_heads_replay_keeps_each_agents_learning_its_own():
    _check_agent_zero_is_its_own(_option_run,
                                 [(0.5, False), (0.0, False), (1.0, True), (0.2, True)],
                                 steps=150)  # fmt: skip


@pytest.mark.slow
def test_a_neural_agents_episodes_do_not_depend_on_when_the_others_finish():
    """The symptom measured on Pinball: the same command for 2 and for 4 episodes. Every
    agent's first two episodes must be the same, though in the 2-episode run the fastest agent
    finishes (and stops storing and learning) while the others are still in their second.
    Same population size on both sides: across sizes, batched matmuls may round the last bits
    differently (so ``verify`` still refuses neural runs)."""
    from tests.neural.test_neural_pieces import neural_agent

    def run(episodes):
        cfg = TrainConfig(agent="skill-chaining", map="pinball_box", runs=3, episodes=episodes,
                          max_episode_steps=600, seed=0)  # fmt: skip
        agent = neural_agent(population=3, seed=0)
        return PopulationTrainer(cfg, agent=agent).train(), agent

    short, _ = run(2)
    long, agent = run(4)
    assert bool(agent.bank.live().any()) and agent.bank.q_head.replay.stored > 0
    assert len(set(short.lengths[:, :2].sum(1).tolist())) == 3  # they finish at different steps
    assert short.returns[:, :2].tolist() == long.returns[:, :2].tolist()


def test_the_learners_resume_bit_for_bit_from_their_state():
    """Saved after 70 calls and loaded into fresh learners (on an explicit device, as the
    agent does with a checkpoint read onto the CPU): the next 50 calls give the same weights
    as 120 uninterrupted ones."""
    def option_learner(steps, state=None):
        head = MLPOptionQHead(2, 2, hidden=8, lr=0.05, q_scale=100.0, seed=5)
        head.replay = OptionReplay(batch_size=4, train_every=2, target_update=5, seed=9)
        if state is not None:
            head.load_state_dict(state[0])
            head.replay.load_state_dict(state[1], device="cpu")
        update = IntraOptionQLearning(gamma=1.0, completion_reward=100.0)
        g = torch.Generator().manual_seed(0)
        for t in range(steps):
            obs = torch.rand(2, 4, generator=g, dtype=F64)
            if state is not None and t < 70:
                continue  # (the saved run took these)
            learn = torch.tensor([[t % 2 == 0, True], [t % 3 == 0, False]])
            update(head, obs, torch.tensor([t % 5, 1]), -torch.ones(2, dtype=F64), obs.flip(0),
                   torch.zeros(2, dtype=torch.bool), learn,
                   torch.tensor([[t % 5 == 0, False], [False, t % 3 == 0]]))  # fmt: skip
        return head

    first = option_learner(70)
    state = (first.state_dict(), first.replay.state_dict())
    resumed, uninterrupted = option_learner(120, state), option_learner(120)
    assert all(torch.equal(a, b) for a, b in zip(resumed.params.values(),
                                                 uninterrupted.params.values()))  # fmt: skip
    assert int(resumed.replay.updates.min()) > 0


def test_a_write_before_the_first_call_reaches_the_target():
    head = MLPQHead(2, 3, 2, hidden=8, value_scale=10.0)
    loss = SMDPSarsaLoss(head, loss_function="smooth_l1", value_scale=10.0, delay_value=True)
    learner = ReplayTD(loss, torch.optim.Adam(head.parameters(), lr=1e-2), batch_size=4,
                       target_update=10_000)  # fmt: skip
    head.set_values(torch.tensor([[False, False, True], [False, False, False]]),
                    torch.full((2, 3), 77.0, dtype=F64))  # agent 0 only
    phi = torch.zeros(2, 2, dtype=F64)
    learner(TensorDict(phi=phi, decision=torch.tensor([0, 1]), decision_return=torch.ones(2),
                       duration=torch.ones(2, dtype=torch.long), next_value=torch.zeros(2),
                       terminated=torch.tensor([False, False]),
                       active=torch.tensor([True, True]), next_phi=phi,
                       next_decision=torch.tensor([2, 2]), batch_size=[2]).to(F64))  # fmt: skip
    with loss.target_value_head_params.to_module(head):
        assert head(phi)[:, 2].tolist() == [77.0, 0.0]  # agent 1's target was not copied


def test_per_agent_seeds_reach_the_replay_streams_and_bad_combinations_are_refused():
    from skillchain_torch.agents import SkillChainingAgent
    from skillchain_torch.agents.pieces import _replay_seed

    assert _replay_seed(7, 1) == 8
    assert _replay_seed(torch.tensor([5, 9]), 1).tolist() == [6, 10]
    head = MLPQHead(4, 17, 2, hidden=8)
    loss = SMDPSarsaLoss(head, loss_function="smooth_l1", value_scale=1000.0, delay_value=True)
    learner = ReplayTD(loss, torch.optim.Adam(head.parameters()), batch_size=4)
    bank = OptionBank(2, 2, MLPOptionQHead(2, 2, hidden=4),
                      MLPInitiationClassifier(2, 2, capacity=8, hidden=4))  # fmt: skip
    with pytest.raises(ValueError, match="no intra_option_primitives"):
        SkillChainingAgent(bank, q_head=head, features=torch.nn.Identity(), top_learner=learner,
                           intra_option_primitives=True)  # fmt: skip


@pytest.mark.parametrize("device", [
    "cpu", pytest.param("cuda", marks=[pytest.mark.cuda, pytest.mark.skipif(
        not torch.cuda.is_available(), reason="no CUDA device on this machine")])])
def test_a_neural_run_resumes_from_its_checkpoint_on_its_device(tmp_path, device):
    """A checkpoint is read onto the CPU; the replay memories, targets and counters go back to
    the run's device (on CUDA they stayed on the CPU and the next step mixed devices)."""
    from skillchain_torch.trainers.outputs.checkpoint import resume_checkpoint

    def config(episodes=3):
        return TrainConfig(agent="skill-chaining", preset="paper", map="pinball_box", runs=2,
                           episodes=episodes, max_episode_steps=150, gestation=1, seed=3,
                           checkpoint_every=1, device=device, top_head="mlp", option_head="mlp",
                           initiation="mlp", epsilon_init=1.0, annealing_steps=100)  # fmt: skip

    whole = PopulationTrainer(config(3)).train()
    part = PopulationTrainer(config(3), out_dir=tmp_path)  # interrupted after 2 episodes
    part.train(max_agent_steps=1)
    while part.episodes_done.min() < 2:
        part.train(max_agent_steps=part.agent_steps + 1)
    resumed = PopulationTrainer(config(3), out_dir=tmp_path)
    resume_checkpoint(tmp_path, resumed)
    memory = resumed.agent.top_learner.memory
    assert memory.count.device.type == device and memory.rng.seeds.device.type == device
    resumed.train()
    assert resumed.returns.tolist() == whole.returns.tolist()


def test_a_learner_saved_with_the_shared_memory_is_refused_in_one_line():
    loss = SMDPSarsaLoss(MLPQHead(2, 3, 2, hidden=4), value_scale=10.0, delay_value=True)
    old = {"buffer": {}, "generator": None, "stored": 3, "updates": 0}
    for learner in (OptionReplay(), ReplayTD(loss, torch.optim.Adam(loss.parameters()))):
        with pytest.raises(ValueError, match="^this checkpoint's replay memory is shared by the "
                                             "population .*without --resume$"):  # fmt: skip
            learner.load_state_dict(old)


def test_the_value_in_force_carries_no_graph_from_step_to_step():
    """Q(s', d) of the decision in force is kept from step to step (q_decision, merged by
    torch.where once some agents stop stepping). With a neural head it carried the head's
    autograd graph, so each step's graph chained onto the last and held its activations: a
    neural Pinball run grew to 23 GB. It is a value now."""
    cfg = TrainConfig(agent="skill-chaining", map="pinball_box", runs=3, episodes=2,
                      max_episode_steps=100, seed=0, top_head="mlp", option_head="mlp",
                      initiation="mlp")  # fmt: skip
    trainer = PopulationTrainer(cfg)
    trainer.train(max_agent_steps=30)
    agent = trainer.agent
    assert any(p.requires_grad for p in agent.q_head.parameters())  # a head that could leak
    stepped = torch.tensor([True, True, False])
    going_on = torch.zeros(3, dtype=torch.bool)  # every stepped agent goes on with its decision
    value = agent._value_in_force(stepped, going_on)  # so the head values them again
    assert not value.requires_grad and value.grad_fn is None
    trainer.train()
    assert agent.q_decision.grad_fn is None
