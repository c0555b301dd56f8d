"""OptionBank files: save and load bit for bit, what a file records, and every damaged,
foreign or contradictory file refused in one line naming it."""


import pytest
import torch
from bank_examples import rand, trained_bank
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from skillchain_torch.options import (
    FourierOptionQHead,
    InitiationClassifier,
    MLPOptionQHead,
    OptionBank,
)
from skillchain_torch.options.bank import FORMAT, FORMAT_VERSION


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
