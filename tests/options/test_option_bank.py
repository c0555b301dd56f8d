"""OptionBank: slots, statuses, targets, save/load, agent export, invariance."""

import doctest
import importlib

import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from skillchain_torch.options import (
    FourierOptionQHead,
    GoalEvent,
    InitiationClassifier,
    MLPOptionQHead,
    OptionBank,
    OptionStatus,
    RegionEvent,
)
from skillchain_torch.options.bank import FORMAT, FORMAT_VERSION

F64 = torch.float64


def rand(shape, seed):
    return torch.rand(shape, dtype=F64, generator=torch.Generator().manual_seed(seed))


def trained_bank(population=3, slots=4, seed=0, q_head=None):
    """A bank with options in various states, weights and classifier data."""
    q_head = q_head or FourierOptionQHead(population, slots, order=1)
    bank = OptionBank(
        population, slots, q_head, InitiationClassifier(population, slots, capacity=32, sweeps=100)
    )
    everyone = torch.ones(population, dtype=torch.bool)
    bank.allocate(everyone, target_event=0, episode=1)
    bank.allocate(everyone, parent=0, episode=2)
    gen = torch.Generator().manual_seed(seed)
    if isinstance(q_head, FourierOptionQHead):
        q_head.weight.copy_(torch.randn(q_head.weight.shape, dtype=F64, generator=gen))
    x = torch.rand(20, 4, dtype=F64, generator=gen)
    for p in range(population):
        bank.classifier.add_examples(p, 0, x, x[:, 0] < 0.5 + 0.1 * p)
    bank.classifier.fit()
    bank.set_status(torch.tensor([[True, False, False, False]] * population),
                    OptionStatus.LEARNING)  # fmt: skip
    return bank


def test_doctest():
    module = importlib.import_module("skillchain_torch.options.bank")
    assert doctest.testmod(module).failed == 0


def test_allocate_fills_first_empty_slot_and_returns_minus_one_when_full():
    bank = OptionBank.build(population=2, slots=3, order=1)
    both = torch.tensor([True, True])
    assert bank.allocate(both, episode=torch.tensor([4, 7])).tolist() == [0, 0]
    assert bank.allocate(torch.tensor([True, False])).tolist() == [1, -1]
    bank.free(torch.tensor([[True, False, False], [False, False, False]]))
    assert bank.status.tolist() == [[0, 1, 0], [1, 0, 0]]
    assert bank.allocate(both, target_event=2).tolist() == [0, 1]  # reuses the freed slot 0
    assert bank.allocate(both).tolist() == [2, 2]
    assert bank.allocate(both).tolist() == [-1, -1] and bank.full().tolist() == [True, True]
    assert bank.created_episode.tolist() == [[-1, -1, -1], [7, -1, -1]]
    assert bank.target_event.tolist() == [[2, -1, -1], [-1, 2, -1]]


def test_allocate_resets_the_slot_parts():
    bank = trained_bank()
    bank.free(torch.tensor([[False] * 4, [True, False, False, False], [False] * 4]))
    assert bank.status[:, 0].tolist() == [2, 0, 2]
    assert bank.allocate(torch.tensor([True, True, False])).tolist() == [2, 0, -1]
    assert not bool(bank.q_head.weight[1, 0].any()) and bool(bank.q_head.weight[0, 0].any())
    assert bank.classifier.count[:, 0].tolist() == [20, 0, 20]
    assert bank.classifier.trained[:, 0].tolist() == [True, False, True]
    assert bank.status[:, 0].tolist() == [2, 1, 2] and bank.parent[1, 0] == -1


def test_live_executable_available():
    bank = trained_bank()
    bank.set_status(torch.tensor([[False, True, False, False]] * 3), OptionStatus.LEARNED)
    assert bank.live()[0].tolist() == [True, True, False, False]
    assert bank.executable()[0].tolist() == [True, True, False, False]
    bank.set_status(torch.tensor([[False, True, False, False]] * 3), OptionStatus.GESTATING)
    assert bank.executable()[0].tolist() == [True, False, False, False]
    obs = torch.tensor([[0.1, 0.5, 0.5, 0.5], [0.95, 0.5, 0.5, 0.5], [0.1, 0.5, 0.5, 0.5]],
                       dtype=F64)  # fmt: skip
    member = bank.classifier.contains(obs)
    assert torch.equal(bank.available(obs), member & bank.executable())
    assert bank.available(obs)[:, 0].tolist() == [True, False, True]
    assert torch.equal(bank.available(obs, contains=torch.zeros_like(member)),
                       torch.zeros_like(member))  # fmt: skip


def test_target_reached_uses_parent_sets_and_base_events():
    bank = trained_bank()  # slot 0 targets event 0, slot 1 targets slot 0's set
    bank.allocate(torch.tensor([True, True, True]), target_event=1)
    events = [GoalEvent(), RegionEvent((0.9, 0.9), 0.05)]
    obs = torch.tensor([[0.1, 0.5, 0.5, 0.5], [0.9, 0.9, 0.5, 0.5], [0.99, 0.5, 0.5, 0.5]],
                       dtype=F64)  # fmt: skip
    terminated = torch.tensor([False, False, True])
    reached = bank.target_reached(obs, terminated, events)
    contains = bank.classifier.contains(obs)
    assert reached[:, 0].tolist() == [False, False, True]
    assert torch.equal(reached[:, 1], contains[:, 0])
    assert reached[:, 2].tolist() == [False, True, False]
    assert not bool(reached[:, 3].any())  # empty slots never fire
    with pytest.raises(ValueError, match="target event 1"):
        bank.target_reached(obs, terminated, events[:1])


def test_save_load_round_trip_is_bit_exact(tmp_path):
    bank = trained_bank()
    path = tmp_path / "bank.pt"
    bank.save(path)
    loaded = OptionBank.load(path)
    assert type(loaded.q_head) is FourierOptionQHead
    original, restored = bank.state_dict(), loaded.state_dict()
    assert original.keys() == restored.keys()
    for key in original:
        assert torch.equal(original[key], restored[key]), key
    obs = rand((3, 4), 5)
    assert torch.equal(loaded.q_head(obs), bank.q_head(obs))
    assert torch.equal(loaded.available(obs), bank.available(obs))
    assert loaded.classifier.config == bank.classifier.config


def test_mlp_bank_round_trip(tmp_path):
    head = MLPOptionQHead(2, 3, hidden=8, seed=4)
    bank = OptionBank(2, 3, head, InitiationClassifier(2, 3, capacity=8))
    bank.save(tmp_path / "mlp.pt")
    loaded = OptionBank.load(tmp_path / "mlp.pt")
    assert type(loaded.q_head) is MLPOptionQHead
    for key, value in bank.state_dict().items():
        assert torch.equal(value, loaded.state_dict()[key]), key


def test_corrupt_or_mismatched_files_raise_value_error(tmp_path):
    bank = trained_bank()
    good = tmp_path / "good.pt"
    bank.save(good)
    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes(good.read_bytes()[:100])
    with pytest.raises(ValueError, match="not a readable OptionBank"):
        OptionBank.load(corrupt)
    foreign = tmp_path / "foreign.pt"
    torch.save({"weight": torch.zeros(3)}, foreign)
    with pytest.raises(ValueError, match="not an OptionBank file"):
        OptionBank.load(foreign)
    payload = bank._payload()
    payload["version"] = FORMAT_VERSION + 1
    torch.save(payload, tmp_path / "future.pt")
    with pytest.raises(ValueError, match="version"):
        OptionBank.load(tmp_path / "future.pt")
    payload = bank._payload()
    del payload["state"]["status"]
    torch.save(payload, tmp_path / "missing.pt")
    with pytest.raises(ValueError, match="does not match"):
        OptionBank.load(tmp_path / "missing.pt")
    with pytest.raises(ValueError, match="does not match"):  # parts of another shape
        OptionBank.load(good, q_head=FourierOptionQHead(3, 4, order=2))
    assert payload["format"] == FORMAT


def test_select_agents_and_from_agent_replicate_one_agent(tmp_path):
    bank = trained_bank(population=3)
    path = tmp_path / "population.pt"
    bank.save(path)
    copies = OptionBank.from_agent(path, agent=2, population=5)
    assert copies.population == 5 and copies.q_head.population == 5
    for key, value in copies.state_dict().items():
        if key.startswith(("q_head.basis", "classifier.features")):
            continue
        for p in range(5):
            assert torch.equal(value[p], bank.state_dict()[key][2]), key
    reseeded = bank.select_agents([0, 0], seeds=torch.tensor([10, 11]))
    assert reseeded.classifier.seeds.tolist() == [10, 11]
    with pytest.raises(ValueError, match="out of range"):
        bank.select_agents([3])


def test_mismatched_parts_raise():
    with pytest.raises(ValueError, match="q_head is for"):
        OptionBank(2, 3, FourierOptionQHead(2, 4, order=1), InitiationClassifier(2, 3))
    bank = OptionBank.build(1, 2, order=1)
    with pytest.raises(ValueError, match="mask must be"):
        bank.set_status(torch.ones(2, 2, dtype=torch.bool), OptionStatus.LEARNED)


def test_population_invariance():
    together = trained_bank(population=4)
    alone = [together.select_agents([p]) for p in range(4)]
    events = [GoalEvent(), RegionEvent((0.5, 0.5), 0.3)]
    gen = torch.Generator().manual_seed(1)
    for _ in range(5):
        obs = torch.rand(4, 4, dtype=F64, generator=gen)
        terminated = torch.rand(4, generator=gen) < 0.3
        available = together.available(obs)
        reached = together.target_reached(obs, terminated, events)
        q = together.q_head(obs)
        for p, bank in enumerate(alone):
            s = slice(p, p + 1)
            assert torch.equal(bank.available(obs[s])[0], available[p])
            assert torch.equal(bank.target_reached(obs[s], terminated[s], events)[0], reached[p])
            assert torch.equal(bank.q_head(obs[s])[0], q[p])
    slot = together.allocate(torch.tensor([True, False, True, True]))
    for p, bank in enumerate(alone):
        mine = bank.allocate(torch.tensor([p != 1]))
        assert mine.item() == slot[p].item()


def test_learning_loop_is_population_invariant():
    """Targets, intra-option Q-learning and classifier fits together: P=4 vs each alone."""
    from skillchain_torch.objectives import IntraOptionQLearning

    together = trained_bank(population=4)
    alone = [together.select_agents([p]) for p in range(4)]
    events = [GoalEvent()]
    update = IntraOptionQLearning()
    gen = torch.Generator().manual_seed(8)

    def step(bank, obs, action, reward, next_obs, terminated):
        contains = bank.classifier.contains(obs)
        reached = bank.target_reached(next_obs, terminated, events)
        delta = update(bank.q_head, obs, action, reward, next_obs, terminated, contains, reached,
                       bank.live())  # fmt: skip
        agents = torch.arange(bank.population)
        bank.classifier.add_examples(agents, 1, obs, reached[:, 1])
        bank.classifier.fit()
        return delta

    for _ in range(4):
        obs, next_obs = (
            torch.rand(4, 4, dtype=F64, generator=gen),
            torch.rand(4, 4, dtype=F64, generator=gen),
        )
        action = torch.randint(0, 5, (4,), generator=gen)
        reward = torch.full((4,), -1.0, dtype=F64)
        terminated = torch.rand(4, generator=gen) < 0.3
        delta = step(together, obs, action, reward, next_obs, terminated)
        assert bool(delta.any())
        for p, bank in enumerate(alone):
            s = slice(p, p + 1)
            mine = step(bank, obs[s], action[s], reward[s], next_obs[s], terminated[s])
            assert torch.equal(mine[0], delta[p])
    for p, bank in enumerate(alone):
        for key, value in bank.state_dict().items():
            if not key.startswith(("q_head.basis", "classifier.features")):
                assert torch.equal(value[0], together.state_dict()[key][p]), key


def test_allocate_wants_an_agent_mask():
    bank = OptionBank.build(2, 2, order=1)
    with pytest.raises(ValueError, match="BoolTensor"):
        bank.allocate(torch.tensor([0, 1]))


# ---------------------------------------------------------------- files: metadata and integrity
def test_saved_bank_records_environment_and_features(tmp_path):
    bank = trained_bank()
    bank.map = "pinball_hard_single"
    bank.save(tmp_path / "bank.pt")
    payload = torch.load(tmp_path / "bank.pt", weights_only=True)
    assert payload["environment"] == {"map": "pinball_hard_single", "obs_dim": 4,
                                      "num_actions": 5}  # fmt: skip
    assert payload["features"] == {"q_head": "FourierOptionQHead", "order": 1,
                                   "initiation_degree": 2, "initiation_centered": False}
    loaded = OptionBank.load(tmp_path / "bank.pt")
    assert loaded.map == "pinball_hard_single" and not loaded.legacy
    assert loaded.select_agents([1, 1]).map == "pinball_hard_single"


def test_bank_for_another_map_is_refused_by_name(tmp_path):
    bank = trained_bank()
    bank.map = "pinball_hard_single"
    bank.save(tmp_path / "bank.pt")
    loaded = OptionBank.load(tmp_path / "bank.pt")
    with pytest.raises(ValueError, match=r"bank.pt: the options were learned with map = "
                       r"'pinball_hard_single', but this run has map = 'pinball_simple_single' "
                       r"\(--map pinball_simple_single\)"):
        loaded.check_environment(tmp_path / "bank.pt", map="pinball_simple_single")
    with pytest.raises(ValueError, match="num_actions = 5, but this run has num_actions = 3"):
        loaded.check_environment("bank.pt", num_actions=3)
    with pytest.raises(ValueError, match="obs_dim = 4, but this run has obs_dim = 2"):
        loaded.check_environment("bank.pt", obs_dim=2)
    loaded.check_environment("bank.pt", map="pinball_hard_single", obs_dim=4, num_actions=5)


def test_bank_saved_before_metadata_still_loads(tmp_path):
    """Published banks have no environment, features or digest: they load, unverified."""
    bank = trained_bank()
    payload = bank._payload()
    del payload["environment"], payload["features"]
    torch.save(payload, tmp_path / "old.pt")
    loaded = OptionBank.load(tmp_path / "old.pt")
    assert loaded.legacy and loaded.map is None
    for key, value in bank.state_dict().items():
        assert torch.equal(value, loaded.state_dict()[key]), key
    loaded.check_environment("old.pt", map="pinball_box", obs_dim=4, num_actions=5)  # unknown map
    with pytest.raises(ValueError, match="num_actions"):  # what can be checked still is
        loaded.check_environment("old.pt", num_actions=4)


def test_recorded_settings_that_contradict_the_parts_are_refused(tmp_path):
    bank = trained_bank()
    payload = bank._payload()
    payload["features"]["order"] = 5
    torch.save(payload, tmp_path / "b.pt")
    with pytest.raises(ValueError, match=r"b.pt: field 'features.order' is 5, but the bank's "
                                         r"parts have 1"):
        OptionBank.load(tmp_path / "b.pt")
    payload = bank._payload()
    payload["environment"]["obs_dim"] = 2
    torch.save(payload, tmp_path / "b.pt")
    with pytest.raises(ValueError, match="'environment.obs_dim' is 2"):
        OptionBank.load(tmp_path / "b.pt")


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf")])
@pytest.mark.parametrize("key", ["q_head.weight", "classifier.weight", "classifier.bias"])
def test_bank_with_non_finite_weights_is_refused(tmp_path, key, bad):
    bank = trained_bank()
    bank.state_dict()[key].view(3, -1)[1, 0] = bad
    bank.save(tmp_path / "bank.pt")
    with pytest.raises(ValueError, match=rf"bank.pt: tensor '{key}' holds 1 NaN or infinite "
                                         r"values \(agents \[1\]\); a diverged bank"):
        OptionBank.load(tmp_path / "bank.pt")


def test_altered_bank_fails_its_checksum(tmp_path):
    bank = trained_bank()
    bank.save(tmp_path / "bank.pt")
    data = bytearray((tmp_path / "bank.pt").read_bytes())
    weight = bank.q_head.weight.numpy().tobytes()
    at = data.find(weight)
    assert at > 0
    data[at + 5] ^= 0x10  # a low bit of one weight: still a plausible, finite number
    (tmp_path / "bank.pt").write_bytes(bytes(data))
    assert torch.isfinite(torch.load(tmp_path / "bank.pt", weights_only=True)["state"][
        "q_head.weight"]).all()  # torch itself reads it without complaint
    with pytest.raises(ValueError, match="bank.pt: checksum mismatch .* altered or damaged"):
        OptionBank.load(tmp_path / "bank.pt")


@pytest.mark.parametrize(
    ("content", "reason"),
    [
        (b"", r"the file is empty"),
        (b"hello, options\n", r"not a torch file: it starts with b'hell'"),
        (None, r"a truncated or damaged torch file"),  # the first half of a good file
        ({"a": 1}, r"not an OptionBank file \(format"),
        (torch.nn.Linear(2, 2), r"holds Python objects \(torch.nn.modules.linear.Linear\)"),
        ({"format_version": 1, "agent": {}, "trainer": {}}, r"it is a training checkpoint"),
    ],
)
def test_unreadable_files_give_one_line(tmp_path, content, reason):
    path = tmp_path / "file.pt"
    if content is None:
        trained_bank().save(tmp_path / "good.pt")
        good = (tmp_path / "good.pt").read_bytes()
        path.write_bytes(good[: len(good) // 2])
    elif isinstance(content, bytes):
        path.write_bytes(content)
    else:
        torch.save(content, path)
    with pytest.raises(ValueError, match=reason) as info:
        OptionBank.load(path)
    assert str(info.value).startswith(f"{path}: ") and "\n" not in str(info.value)


def _fuzz_outcome(path, original: OptionBank | None) -> None:
    """Loading ``path`` gives a one-line ValueError naming it, or the original contents."""
    try:
        loaded = OptionBank.load(path)
    except ValueError as error:
        text = str(error)
        assert text.startswith(f"{path}: ") and "\n" not in text and len(text) < 600, text
        return
    assert original is not None, "random bytes loaded as a bank"
    for key, value in original.state_dict().items():
        assert torch.equal(value, loaded.state_dict()[key]), key


_FUZZ = settings(max_examples=40, deadline=None,
                 suppress_health_check=[HealthCheck.function_scoped_fixture])


@_FUZZ
@given(data=st.binary(max_size=4096))
def test_fuzz_bank_loader_on_random_bytes(tmp_path, data):
    path = tmp_path / "random.pt"
    path.write_bytes(data)
    _fuzz_outcome(path, None)


@_FUZZ
@given(cut=st.integers(min_value=0, max_value=1 << 30),
       flips=st.lists(st.tuples(st.integers(min_value=0, max_value=1 << 30),
                                st.integers(min_value=1, max_value=255)), max_size=4))
def test_fuzz_bank_loader_on_corrupted_files(tmp_path, cut, flips):
    bank = trained_bank()
    good = tmp_path / "good.pt"
    if not good.exists():
        bank.save(good)
    data = bytearray(good.read_bytes())
    for at, mask in flips:
        data[at % len(data)] ^= mask
    if cut % 3 == 0:  # a third of the cases truncated too
        del data[cut % len(data):]
    path = tmp_path / "corrupted.pt"
    path.write_bytes(bytes(data))
    _fuzz_outcome(path, bank)
