"""``store_failures``: a full initiation-set store never rejects a failure's start state.

A plain reservoir keeps the ``n``-th example with probability ``C / (n + 1)``; late in a run
a slot has seen tens of thousands of examples and almost no failure is stored.
"""

import pytest
import torch
from bank_examples import compiled_stores_agree

from skillchain_torch.backends import initiation as native_initiation
from skillchain_torch.options import InitiationClassifier, OptionBank
from skillchain_torch.options.examples import failure_place

F64 = torch.float64
PATHS = [False, pytest.param(True, marks=pytest.mark.skipif(
    not native_initiation.AVAILABLE, reason="compiled classifier not built"))]


def _full_store(native: bool, store_failures: bool, keep_negatives: bool = True):
    clf = InitiationClassifier(population=1, slots=1, capacity=40, sweeps=0,
                               keep_negatives=keep_negatives, store_failures=store_failures)
    clf.set_native(native)
    gen = torch.Generator().manual_seed(3)
    for _ in range(50):  # 50 successes of 100 states: seen = 5,000, the store all positives
        clf.add_examples(0, 0, torch.rand(100, 4, dtype=F64, generator=gen), torch.ones(100))
    return clf, gen


@pytest.mark.parametrize("native", PATHS)
def test_every_failure_enters_a_full_store(native):
    clf, gen = _full_store(native, store_failures=True)
    failures = torch.rand(12, 4, dtype=F64, generator=gen)
    for i in range(12):
        clf.add_examples(0, 0, failures[i:i + 1], torch.zeros(1))
        assert int((~clf.labels[0, 0]).sum()) == i + 1  # each one stored, none replaced
    stored = clf.examples[0, 0][~clf.labels[0, 0]]
    assert torch.equal(stored[stored[:, 0].argsort()], failures[failures[:, 0].argsort()])
    assert int(clf.seen[0, 0]) == 5012 and int(clf.count[0, 0]) == 40


@pytest.mark.parametrize("native", PATHS)
def test_without_it_the_reservoir_drops_nearly_every_failure(native):
    clf, gen = _full_store(native, store_failures=False)
    for _ in range(12):
        clf.add_examples(0, 0, torch.rand(1, 4, dtype=F64, generator=gen), torch.zeros(1))
    assert int((~clf.labels[0, 0]).sum()) <= 2  # each kept with probability 40 / 5,000


@pytest.mark.parametrize("native", PATHS)
def test_a_store_of_failures_only_replaces_the_drawn_place(native):
    clf = InitiationClassifier(population=1, slots=1, capacity=4, sweeps=0,
                               keep_negatives=True, store_failures=True)
    clf.set_native(native)
    x = torch.rand(10, 4, dtype=F64, generator=torch.Generator().manual_seed(0))
    clf.add_examples(0, 0, x[:4], torch.zeros(4))
    for i in range(4, 10):  # no positive left to replace: still stored, at the drawn place
        clf.add_examples(0, 0, x[i:i + 1], torch.zeros(1))
        assert bool((clf.examples[0, 0] == x[i]).all(-1).any())
    assert int(clf.count[0, 0]) == 4 and not bool(clf.labels.any())


def test_failure_place_takes_the_first_positive_from_the_draw_on():
    z = torch.tensor(0)
    labels = torch.tensor([True, False, False, True, False])
    places = {failure_place(z, z, z, torch.tensor(i), 5, labels) for i in range(5, 60)}
    assert places == {0, 3}  # only positives are replaced, and both are reachable
    assert failure_place(z, z, z, torch.tensor(7), 5, torch.zeros(5, dtype=torch.bool)) in range(5)


@pytest.mark.skipif(not native_initiation.AVAILABLE, reason="compiled classifier not built")
@pytest.mark.parametrize("keep_negatives", [True, False])
def test_same_stores_torch_and_compiled(keep_negatives):
    compiled = compiled_stores_agree(60, keep_negatives=keep_negatives, store_failures=True)
    assert int((~compiled.labels).sum()) > 10


def test_saved_with_the_bank(tmp_path):
    bank = OptionBank.build(population=1, slots=2, order=1, store_failures=True)
    bank.save(tmp_path / "options.pt")
    assert OptionBank.load(tmp_path / "options.pt").classifier.store_failures
    plain = OptionBank.build(population=1, slots=2, order=1)
    assert "store_failures" not in plain.classifier.config  # older files read unchanged


def test_the_flag_reaches_the_classifier(tmp_path):
    import json

    from skillchain_torch.agents import SkillChainingAgent
    from skillchain_torch.trainers.config.cli import main

    agent = SkillChainingAgent.build(population=1, slots=2, order=1, store_failures=True)
    assert agent.bank.classifier.store_failures
    built = SkillChainingAgent.build(population=1, slots=2, order=1)
    assert not built.bank.classifier.store_failures  # the default preset's reading
    out = tmp_path / "run"
    assert main(["train", "--agent", "skill-chaining", "--store-failures", "on",
                 "--constrain-nearest", "on", "--runs", "1", "--episodes", "1",
                 "--max-episode-steps", "50", "--quiet", "--out", str(out)]) == 0
    saved = json.loads((out / "config.json").read_text())
    assert saved["store_failures"] is True and saved["constrain_nearest"] is True
