"""Option monitoring: Figure-5 densities, per-option counters, TensorBoard tags."""

import doctest
import importlib

import numpy as np
import pytest
import torch
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from skillchain_torch.agents import HierarchicalAgent
from skillchain_torch.agents.region_option import make_region_option
from skillchain_torch.envs.pinball import load_map
from skillchain_torch.options import InitiationClassifier, LambdaEvent, OptionBank, OptionStatus
from skillchain_torch.trainers import PopulationTrainer, TensorBoardHook, TrainConfig
from skillchain_torch.trainers.outputs.option_monitor import (
    VELOCITIES,
    OptionMonitor,
    SlotMemo,
    contains_many,
    initiation_density,
    initiation_image,
    plot_initiation_set,
    probe_observations,
)

# Polynomial feature indices (dim 4, degree 2): 1, x, y, xd, yd, x^2, xy, ..., y^2 = 9.
X, Y, XD, X2, Y2 = 1, 2, 3, 5, 9


@pytest.mark.parametrize("name", ["outputs.option_monitor", "outputs.initiation_images"])
def test_doctests(name):
    module = importlib.import_module(f"skillchain_torch.trainers.{name}")
    assert doctest.testmod(module, optionflags=doctest.ELLIPSIS).failed == 0


def disc_classifier(center=(0.3, 0.6), radius=0.2) -> InitiationClassifier:
    """Slot 0: the disc ||(x, y) - center|| < radius (any velocity), as a RegionEvent;
    slot 1: xdot descriptor > 0.6, i.e. raw xdot in {1/2, 1} of the Figure-5 velocities."""
    clf = InitiationClassifier(population=2, slots=2)
    cx, cy = center
    with torch.no_grad():
        w = clf.weight[1, 0]
        w[X2], w[Y2], w[X], w[Y] = -1.0, -1.0, 2 * cx, 2 * cy
        clf.bias[1, 0] = radius**2 - cx**2 - cy**2
        clf.weight[1, 1, XD] = 1.0
        clf.bias[1, 1] = -0.6
        clf.trained[1] = True
    return clf


def test_density_of_a_disc():
    center, radius, res = (0.3, 0.6), 0.2, 50
    clf = disc_classifier(center, radius)
    d = initiation_density(clf, agent=1, slot=0, resolution=res)
    assert d.shape == (res, res)
    c = (np.arange(res) + 0.5) / res
    yy, xx = np.meshgrid(c, c, indexing="ij")  # row = y, column = x
    inside = (xx - center[0]) ** 2 + (yy - center[1]) ** 2 < radius**2
    assert set(np.unique(d)) <= {0.0, 1.0}  # velocity-independent set
    np.testing.assert_array_equal(d == 1.0, inside)
    # Orientation: the disc's centre cell is lit, a far corner is not.
    assert d[int(center[1] * res), int(center[0] * res)] == 1.0 and d[0, -1] == 0.0


def test_density_counts_velocity_combinations():
    clf = disc_classifier()
    d = initiation_density(clf, agent=1, slot=1, resolution=8)
    np.testing.assert_allclose(d, 10 / 25)  # 2 of 5 xdot values x all 5 ydot values
    # An untrained slot contains everything; the bank and the classifier give the same.
    np.testing.assert_array_equal(initiation_density(clf, agent=0, slot=0, resolution=8), 1.0)


def test_density_of_a_constrained_set():
    clf = InitiationClassifier(1, 1, distance=0.1, distance_dims=(0, 1))
    example = torch.tensor([[0.5, 0.5, 0.5, 0.5]], dtype=torch.float64)
    clf.add_examples(0, 0, example, torch.tensor([True]))
    with torch.no_grad():
        clf.trained[0, 0] = True
        clf.bias[0, 0] = 1.0  # the logistic part contains everything
    clf.constrain(torch.tensor([[True]]))
    d = initiation_density(clf, 0, 0, resolution=20)
    c = (np.arange(20) + 0.5) / 20
    yy, xx = np.meshgrid(c, c, indexing="ij")
    np.testing.assert_array_equal(d == 1.0, (xx - 0.5) ** 2 + (yy - 0.5) ** 2 <= 0.01)


def test_contains_many_matches_contains():
    bank = make_region_option(examples=200, pretrain_steps=2, batch=4)
    clf = bank.classifier
    obs = torch.rand(300, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(1))
    many = contains_many(clf, 0, 0, obs)
    one = torch.stack([clf.contains(o[None])[0, 0] for o in obs])
    assert torch.equal(many, one) and 0 < int(many.sum()) < 300
    assert initiation_density(bank, 0, 0, resolution=10).max() > 0


def test_probe_grid_and_images():
    obs = probe_observations(3)
    assert obs.shape == (3 * 3 * 25, 4)
    assert set(obs[:, 2].unique().tolist()) == {(v + 1) / 2 for v in VELOCITIES}
    grid = obs.reshape(3, 3, 25, 4)
    assert torch.all(grid[1, 2, :, 0] == 2.5 / 3) and torch.all(grid[1, 2, :, 1] == 1.5 / 3)
    image = initiation_image(np.full((10, 10), 0.5), load_map("pinball_simple_single"), scale=2)
    assert image.shape == (20, 20, 3) and image.dtype == np.uint8
    ax = plot_initiation_set(disc_classifier(), 1, 0, load_map("pinball_simple_single"),
                             resolution=10)
    assert ax.images[0].get_array().shape == (10, 10)


def scripted_agent(event, max_option_steps=7):
    """Two agents, one option (slot 0, everywhere) that the top level always picks."""
    bank = OptionBank.build(population=2, slots=2, order=1)
    bank.status[:, 0] = int(OptionStatus.LEARNED)
    bank.target_event[:, 0] = 0
    agent = HierarchicalAgent(bank, order=1, epsilon=0.0, option_epsilon=0.0, events=(event,),
                              max_option_steps=max_option_steps)
    with torch.no_grad():
        agent.q_head.weight[:, 5, 0] = 1e6  # the constant feature: option 0 always preferred
    return agent


def run_episode(agent, xs):
    """Feed the observations with x from ``xs``; the last step terminates (both agents)."""
    obs = lambda x: torch.tensor([[x, 0.5, 0.5, 0.5]] * 2, dtype=torch.float64)  # noqa: E731
    reward = torch.full((2,), -1.0, dtype=torch.float64)
    agent.begin(obs(0.1))
    for x in xs[:-1]:
        agent.observe(obs(x), reward)
    ones = torch.ones(2, dtype=torch.bool)
    empty = torch.zeros(0, dtype=torch.int64)
    agent.observe_ends(obs(xs[-1]), reward, ones, ~ones, empty, None)


@pytest.mark.parametrize("numpy", [True, False])  # the CPU's NumPy counting, the torch one
def test_counters_timeouts(numpy):
    agent = scripted_agent(LambdaEvent(lambda o: torch.zeros(o.shape[0], dtype=torch.bool),
                                       "never"))
    monitor = OptionMonitor().attach(agent)
    monitor._numpy = numpy
    run_episode(agent, [0.2] * 20)  # 20 steps: executions end at 7, 14 (timeouts) and 20
    counts = monitor.end_episodes([0, 1], [0, 0])
    np.testing.assert_array_equal(counts["steps"], [20, 20])
    np.testing.assert_array_equal(counts["option_steps"], [[20, 0]] * 2)
    np.testing.assert_array_equal(counts["executions"], [[3, 0]] * 2)
    np.testing.assert_array_equal(counts["execution_steps"], [[20, 0]] * 2)
    np.testing.assert_array_equal(counts["timeouts"], [[2, 0]] * 2)
    np.testing.assert_array_equal(counts["successes"], [[0, 0]] * 2)
    stats = monitor.episode_stats(0)
    assert stats["step_share"][0] == 1.0 and stats["primitive_step_share"] == 0.0
    assert stats["executions"][0] == 3 and np.isclose(stats["mean_duration"][0], 20 / 3)
    assert stats["success_rate"][0] == 0 and np.isclose(stats["timeout_rate"][0], 2 / 3)
    assert np.isnan(stats["mean_duration"][1])
    assert monitor.counts()["steps"].tolist() == [0, 0]  # reset after the episode
    monitor.detach()
    assert not agent._transition_hooks  # the hook is gone


@pytest.mark.parametrize("numpy", [True, False])
def test_counters_successes(numpy):
    agent = scripted_agent(LambdaEvent(lambda o: o[:, 0] > 0.5, "right"), max_option_steps=100)
    monitor = OptionMonitor().attach(agent)
    monitor._numpy = numpy
    # Steps 1-3 left, 4 right (success), 5-6 left, 7 right (success), 8-9 left, episode end.
    run_episode(agent, [0.2, 0.2, 0.2, 0.8, 0.2, 0.2, 0.8, 0.2, 0.2])
    counts = monitor.end_episodes([0, 1], [0, 0])
    np.testing.assert_array_equal(counts["executions"][:, 0], [3, 3])
    np.testing.assert_array_equal(counts["successes"][:, 0], [2, 2])
    np.testing.assert_array_equal(counts["execution_steps"][:, 0], [9, 9])
    np.testing.assert_array_equal(counts["timeouts"][:, 0], [0, 0])
    assert np.isclose(monitor.episode_stats(0)["success_rate"][0], 2 / 3)


@pytest.fixture(scope="module")
def option_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("options")
    make_region_option(examples=200, pretrain_steps=20, batch=20).save(out / "opt.pt")
    cfg = TrainConfig(agent="given-options", options=str(out / "opt.pt"), runs=2, episodes=3,
                      seed=0, max_episode_steps=150)
    trainer = PopulationTrainer(cfg, out_dir=None)
    hook = TensorBoardHook.for_run(trainer, out)
    hook.register(trainer)
    hook.option_monitor.image_every = 2
    hook.option_monitor.image_resolution = 20
    trainer.train()
    hook.close()
    events = EventAccumulator(str(out / "tb" / f"given-options_{cfg.map}_P2_seed0"),
                              size_guidance={"images": 0})
    events.Reload()
    return trainer, hook, events


def test_event_file(option_run):
    trainer, hook, events = option_run
    tags = set(events.Tags()["scalars"])
    for key in ("step_share", "executions", "initiation_size"):
        assert f"options/slot_0/{key}" in tags
        # Every population episode, but the probed sizes: the first, every size_every (10),
        # and the end.
        steps = [1, 3] if key == "initiation_size" else [1, 2, 3]
        assert [e.step for e in events.Scalars(f"options/slot_0/{key}")] == steps
    assert {"options/primitive_step_share", "options/live_slots"} <= tags
    for e in events.Scalars("options/slot_0/step_share"):
        assert 0.0 <= e.value <= 1.0
    size = events.Scalars("options/slot_0/initiation_size")[0].value
    assert 0.0 < size < 0.5  # the region around the target: a small part of the board
    images = events.Images("options/initiation/agent_0/slot_0")
    assert [e.step for e in images] == [1, 3]  # the first, then every 2 / at the end
    assert (images[0].width, images[0].height) == (80, 80)


def test_monitor_does_not_change_training(option_run):
    trainer, _, _ = option_run
    cfg = trainer.config
    plain = PopulationTrainer(cfg).train()
    np.testing.assert_array_equal(plain.returns, trainer.returns)


def test_numpy_and_torch_counting_agree_on_a_run():
    config = TrainConfig(agent="skill-chaining", map="pinball_box", runs=3, episodes=4, seed=0)
    trainer = PopulationTrainer(config)
    monitors = [OptionMonitor(), OptionMonitor()]
    for monitor, numpy in zip(monitors, (True, False)):
        monitor.register(trainer, name=f"options_{numpy}")
        monitor._numpy = numpy
    trainer.train()
    a, b = (m._totals for m in monitors)
    assert a.keys() == b.keys() == set(range(4))
    for e in a:
        for name in a[e]:
            np.testing.assert_array_equal(a[e][name], b[e][name])
    assert sum(int(t["executions"].sum()) for t in a.values()) > 0


class Shifted(InitiationClassifier):
    """A user's classifier: the built-in one, read at x - 0.25."""

    def contains_points(self, agent, slot, obs):
        return super().contains_points(agent, slot, obs - torch.tensor([0.25, 0, 0, 0]))


def test_slot_memo_answers_as_a_fresh_call():
    clf = disc_classifier()
    memo = SlotMemo(probe_observations(6))
    fresh = lambda: contains_many(clf, 1, 0, memo.probe)  # noqa: E731
    assert torch.equal(memo.contains(clf, 1, 0), fresh())
    assert torch.equal(memo.contains(clf, 1, 0), fresh()) and (memo.misses, memo.hits) == (1, 1)
    # New examples: constrained, the stored positives decide; then a refit moves the weights.
    obs = torch.rand(40, 4, dtype=torch.float64, generator=torch.Generator().manual_seed(0))
    clf.add_examples(1, 0, obs, obs[:, 0] < 0.4)
    with torch.no_grad():
        clf.constrained[1, 0] = True
    assert torch.equal(memo.contains(clf, 1, 0), fresh()) and memo.misses == 2
    clf.fit()
    assert torch.equal(memo.contains(clf, 1, 0), fresh()) and memo.misses == 3
    assert torch.equal(memo.contains(clf, 1, 0), fresh()) and memo.hits == 2
    # A classifier of the user's own is asked every time.
    user = Shifted(population=2, slots=2)
    user.load_state_dict(clf.state_dict())
    for _ in range(2):
        assert torch.equal(memo.contains(user, 1, 0), user.contains_points(1, 0, memo.probe))
    assert memo.misses == 5


def test_agent_kept_counts_agree_with_counting_every_step():
    config = TrainConfig(agent="skill-chaining", map="pinball_box", runs=3, episodes=4, seed=0,
                         max_episode_steps=100_000)  # no truncation: the two counts agree
    trainer = PopulationTrainer(config)
    monitors = [OptionMonitor(counting="step"), OptionMonitor(counting="agent")]
    for i, monitor in enumerate(monitors):
        monitor.register(trainer, name=f"options_{i}")
    assert monitors[1]._kept is not None and len(trainer.agent._transition_hooks) == 1
    trainer.train()
    a, b = (m._totals for m in monitors)
    assert a.keys() == b.keys() == set(range(4))
    for e in a:
        for name in a[e]:
            np.testing.assert_array_equal(a[e][name], b[e][name], err_msg=f"{e} {name}")
    assert sum(int(t["executions"].sum()) for t in a.values()) > 0


def test_the_logger_reads_the_collectors_batches(tmp_path):
    """The trainer hands each hook the collector's batch ([T, n] transitions, the option in
    force at every step); the TensorBoard hook logs the share of agent steps taken inside an
    option from them, between population points."""
    make_region_option(examples=200, pretrain_steps=20, batch=20).save(tmp_path / "opt.pt")
    cfg = TrainConfig(agent="given-options", options=str(tmp_path / "opt.pt"), runs=2,
                      episodes=3, seed=0, max_episode_steps=150)
    trainer = PopulationTrainer(cfg, out_dir=None)
    hook = TensorBoardHook.for_run(trainer, tmp_path, options=False)
    hook.register(trainer)
    seen = {"inside": 0, "steps": 0, "shares": []}

    def count(trainer, batch):
        td = batch.transitions
        assert td.batch_size[1] == len(td["agent"][0]) and td["next", "done"][-1].any()
        assert not td["next", "done"][:-1].any()  # a batch ends where episodes end
        seen["inside"] += int((td["option"] >= 0).sum())
        seen["steps"] += td["option"].numel()
        if batch.population_episode is not None:
            seen["shares"].append(seen["inside"] / seen["steps"])
            seen["inside"] = seen["steps"] = 0

    trainer.register_op("post_episodes", count, name="count")
    trainer.train()
    hook.close()
    events = EventAccumulator(str(tmp_path / "tb" / f"given-options_{cfg.map}_P2_seed0"))
    events.Reload()
    logged = [e.value for e in events.Scalars("population/option_step_share")]
    assert len(logged) == 3 and np.allclose(logged, seen["shares"])
    assert all(0.0 <= v <= 1.0 for v in logged)
    assert seen["steps"] == 0 and int(trainer.lengths.sum()) > 0
