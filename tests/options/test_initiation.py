"""InitiationClassifier: default true, learning, sweeps, capped store, constraint, invariance."""

import doctest
import importlib

import pytest
import torch
from bank_examples import compiled_stores_agree

from skillchain_torch.options import InitiationClassifier, reservoir_uniform

F64 = torch.float64


def rand(shape, seed):
    return torch.rand(shape, dtype=F64, generator=torch.Generator().manual_seed(seed))


@pytest.mark.parametrize("name", ["initiation", "logistic", "examples"])
def test_doctest(name):
    module = importlib.import_module(f"skillchain_torch.options.{name}")
    assert doctest.testmod(module).failed == 0


def test_parameterisation_reads_as_logistic_regression():
    clf = InitiationClassifier(population=3, slots=8)
    assert clf.weight.shape == (3, 8, 15) and clf.bias.shape == (3, 8)
    assert {name for name, _ in clf.named_parameters()} == {"weight", "bias"}
    assert clf.examples.shape == (3, 8, 500, 4)
    obs = rand((3, 4), 0)
    z = clf.logit(obs)
    assert torch.allclose(clf.probability(obs), torch.sigmoid(z), rtol=1e-15)


def test_true_everywhere_before_data():
    clf = InitiationClassifier(population=2, slots=3)
    for seed in range(5):
        assert bool(clf.contains(rand((2, 4), seed)).all())
    clf.add_examples(0, 1, rand((3, 4), 9), torch.zeros(3))  # data but no fit yet
    assert bool(clf.contains(rand((2, 4), 1)).all())


def test_learns_a_linearly_separable_set():
    clf = InitiationClassifier(population=1, slots=2)
    gen = torch.Generator().manual_seed(0)
    for _ in range(3):
        x = torch.rand(60, 4, dtype=F64, generator=gen)
        clf.add_examples(0, 0, x, x[:, 0] < 0.5)
        clf.fit()
    test = torch.rand(2000, 4, dtype=F64, generator=gen)
    member = torch.cat([clf.contains(test[i : i + 1])[:, 0] for i in range(0, 2000, 1)])
    accuracy = (member == (test[:, 0] < 0.5)).to(F64).mean().item()
    assert accuracy > 0.95
    assert bool(clf.trained[0, 0]) and not bool(clf.trained[0, 1])


def test_fit_runs_sweeps_per_addition_and_only_on_chosen_slots():
    clf = InitiationClassifier(population=2, slots=2, sweeps=100)
    clf.add_examples(torch.tensor([0, 0, 1]), torch.tensor([0, 0, 1]), rand((3, 4), 0),
                     torch.tensor([1, 0, 1]))  # fmt: skip
    assert clf.dirty.tolist() == [[True, False], [False, True]]
    before = clf.snapshot()
    fitted = clf.fit(torch.tensor([[True, True], [False, False]]))
    assert fitted.tolist() == [[True, False], [False, False]]  # slot (0, 1) has no data
    assert clf.sweeps_done.tolist() == [[100, 0], [0, 0]]
    assert torch.equal(clf.snapshot()[1], before[1]) and torch.equal(
        clf.snapshot()[0, 1], before[0, 1]
    )
    assert clf.dirty.tolist() == [[False, False], [False, True]]
    clf.fit()  # default: the slots with new data
    assert clf.sweeps_done.tolist() == [[100, 0], [0, 100]]
    clf.add_examples(0, 0, rand((1, 4), 1), torch.tensor([True]))
    clf.fit()
    assert clf.sweeps_done.tolist() == [[200, 0], [0, 100]]


def test_sweeps_are_full_batch_gradient_steps():
    clf = InitiationClassifier(population=1, slots=1, lr=0.5, sweeps=2)
    x = rand((5, 4), 3)
    y = torch.tensor([1.0, 0.0, 1.0, 1.0, 0.0], dtype=F64)
    clf.add_examples(0, 0, x, y)
    clf.fit()
    phi = clf.features(x)
    w, b = torch.zeros(15, dtype=F64), torch.zeros((), dtype=F64)
    for _ in range(2):
        err = torch.sigmoid(phi @ w + b) - y
        w, b = w - 0.5 * (phi.T @ err) / 5, b - 0.5 * err.mean()
    assert torch.allclose(clf.weight[0, 0], w, rtol=1e-12) and torch.allclose(clf.bias[0, 0], b)


@pytest.mark.parametrize("replacement", ["reservoir", "ring"])
def test_store_is_capped_and_fit_work_bounded(replacement):
    cap = 50
    clf = InitiationClassifier(population=2, slots=2, capacity=cap, replacement=replacement)
    gen = torch.Generator().manual_seed(0)
    for i in range(12):
        x = torch.rand(40, 4, dtype=F64, generator=gen)
        x[:, 3] = i  # tag the batch
        clf.add_examples(torch.tensor([0] * 30 + [1] * 10), 1, x, x[:, 0] < 0.5)
        clf.fit()
        assert bool((clf.count <= cap).all())
        # a fit's sweeps run over fit_length(count) places: bounded by the store, whatever
        # was seen (the timing itself is benchmarks' business)
        assert int(clf.fit_length(clf.count).max()) <= cap
    assert clf.seen[:, 1].tolist() == [360, 120] and clf.count[:, 1].tolist() == [cap, cap]
    tags = clf.examples[0, 1, :, 3]
    if replacement == "ring":  # the newest 50 of agent 0's 360 examples
        assert sorted(tags.tolist()) == [10.0] * 20 + [11.0] * 30
    else:  # a spread sample of all batches, old ones included
        assert float(tags.min()) < 6 and float(tags.max()) >= 9


def test_reservoir_keeps_a_uniform_sample():
    cap, n = 100, 2000
    clf = InitiationClassifier(population=1, slots=1, capacity=cap, sweeps=0)
    x = torch.zeros(n, 4, dtype=F64)
    x[:, 0] = torch.arange(n, dtype=F64)
    for chunk in torch.split(torch.arange(n), 137):  # several calls, as episodes would
        clf.add_examples(0, 0, x[chunk], torch.ones(len(chunk)))
    kept = clf.examples[0, 0, :, 0]
    assert clf.count.item() == cap and len(set(kept.tolist())) == cap
    # Uniform over the history: about half the kept examples come from the first half.
    assert 30 <= int((kept < n / 2).sum()) <= 70
    # One call with everything gives the same store (the draws are a pure function).
    one = InitiationClassifier(population=1, slots=1, capacity=cap, sweeps=0)
    one.add_examples(0, 0, x, torch.ones(n))
    assert torch.equal(one.examples, clf.examples)
    u = reservoir_uniform(torch.tensor([3]), torch.tensor([1]), torch.tensor([0]),
                          torch.arange(5))  # fmt: skip
    assert bool(((u >= 0) & (u < 1)).all())


def test_distance_constraint_excludes_points_far_from_positives():
    clf = InitiationClassifier(population=1, slots=1, distance=0.1)
    x = rand((40, 4), 0) * 0.2  # positives in a small corner
    clf.add_examples(0, 0, x, torch.ones(40))
    clf.fit()
    far = torch.tensor([[0.9, 0.9, 0.5, 0.5]], dtype=F64)
    near = x[:1] + torch.tensor([[0.05, 0.0, 0.0, 0.05]], dtype=F64)
    assert bool(clf.contains(far)[0, 0]) and bool(clf.contains(near)[0, 0])  # all positive
    clf.constrain(torch.ones(1, 1, dtype=torch.bool))
    assert not bool(clf.contains(far)[0, 0]) and bool(clf.contains(near)[0, 0])
    # The distance is Euclidean over all four observation dims.
    off = x[:1].clone()
    off[0, 3] += 0.5
    assert not bool(clf.near_positive(off)[0, 0])
    positional = InitiationClassifier(population=1, slots=1, distance_dims=(0, 1))
    positional.add_examples(0, 0, x, torch.ones(40))
    assert bool(positional.near_positive(off)[0, 0])


def test_negative_examples_do_not_count_as_anchors():
    clf = InitiationClassifier(population=1, slots=1)
    clf.add_examples(0, 0, torch.full((1, 4), 0.5, dtype=F64), torch.tensor([False]))
    assert not bool(clf.near_positive(torch.full((1, 4), 0.5, dtype=F64))[0, 0])


def test_weight_change_and_reset():
    clf = InitiationClassifier(population=2, slots=2)
    before = clf.snapshot()
    clf.add_examples(1, 0, rand((10, 4), 0), torch.ones(10))
    clf.fit()
    change = clf.weight_change(before)
    expected = (clf.snapshot() - before).abs().mean(-1)
    assert torch.allclose(change, expected, rtol=1e-14) and change[1, 0] > 0
    assert change[0].tolist() == [0.0, 0.0]
    clf.constrain(torch.tensor([[False, False], [True, False]]))
    clf.reset_slot(1, 0)
    assert clf.count[1, 0] == 0 and not bool(clf.trained[1, 0] | clf.constrained[1, 0])
    assert clf.generation.tolist() == [[0, 0], [1, 0]]
    assert bool(clf.contains(rand((2, 4), 3)).all())


def test_bad_inputs_raise():
    clf = InitiationClassifier(population=2, slots=3)
    with pytest.raises(ValueError, match="obs must be"):
        clf.contains(torch.zeros(3, 4))
    with pytest.raises(ValueError, match=r"obs must be \[N, 4\]"):
        clf.add_examples(0, 0, torch.zeros(5, 3), torch.zeros(5))
    with pytest.raises(ValueError, match="labels"):
        clf.add_examples(0, 0, torch.zeros(5, 4), torch.zeros(4))
    with pytest.raises(ValueError, match="out of range"):
        clf.add_examples(0, 3, torch.zeros(1, 4), torch.zeros(1))
    with pytest.raises(ValueError, match="mask must be"):
        clf.fit(torch.ones(2, 2, dtype=torch.bool))
    with pytest.raises(ValueError, match="replacement"):
        InitiationClassifier(1, 1, replacement="fifo")
    with pytest.raises(ValueError, match="snapshots"):
        clf.weight_change(torch.zeros(1))


@pytest.mark.parametrize("cap", [40, 500])
def test_population_invariance(cap):
    population, slots = 4, 3
    together = InitiationClassifier(population, slots, capacity=cap, sweeps=20)
    alone = [together.select_agents([p]) for p in range(population)]
    gen = torch.Generator().manual_seed(2)
    for _ in range(4):
        n = 60 if cap < 100 else 700
        agents = torch.randint(0, population, (n,), generator=gen)
        ks = torch.randint(0, slots, (n,), generator=gen)
        x = torch.rand(n, 4, dtype=F64, generator=gen)
        labels = x[:, 0] + 0.3 * x[:, 2] < 0.6
        together.add_examples(agents, ks, x, labels)
        together.fit()
        for p, clf in enumerate(alone):
            mine = agents == p
            clf.add_examples(0, ks[mine], x[mine], labels[mine])
            clf.fit()
        together.constrain(torch.rand(population, slots, generator=gen) < 0.3)
        for p, clf in enumerate(alone):
            clf.constrained.copy_(together.constrained[p : p + 1])
    obs = torch.rand(population, 4, dtype=F64, generator=gen)
    logit, member = together.logit(obs), together.contains(obs)
    for p, clf in enumerate(alone):
        for name, value in clf.state_dict().items():
            if not name.startswith("features."):
                assert torch.equal(value[0], together.state_dict()[name][p]), name
        assert torch.equal(clf.logit(obs[p : p + 1])[0], logit[p])
        assert torch.equal(clf.contains(obs[p : p + 1])[0], member[p])


def test_near_positive_on_some_slots_equals_the_full_check():
    clf = InitiationClassifier(population=3, slots=4, capacity=30, distance=0.3)
    gen = torch.Generator().manual_seed(4)
    x = torch.rand(200, 4, dtype=F64, generator=gen)
    clf.add_examples(torch.randint(0, 3, (200,), generator=gen), torch.arange(200) % 4, x,
                     x[:, 1] < 0.5)  # fmt: skip
    obs = torch.rand(3, 4, dtype=F64, generator=gen)
    full = clf.near_positive(obs)
    assert bool(full.any()) and not bool(full.all())
    some = torch.rand(3, 4, generator=gen) < 0.5
    assert torch.equal(clf.near_positive(obs, some), full & some)


def test_balanced_fit_lets_one_failure_outvote_many_successes():
    # 40 positives around x = 0.7 and one negative at x = 0.2 (a failed start state).
    g = torch.Generator().manual_seed(3)
    pos = torch.rand(40, 4, dtype=torch.float64, generator=g) * 0.2 + 0.6
    neg = torch.tensor([[0.2, 0.7, 0.7, 0.7]], dtype=torch.float64)
    obs = torch.cat([pos, neg])
    labels = torch.cat([torch.ones(40, dtype=torch.bool), torch.zeros(1, dtype=torch.bool)])
    logits = {}
    for balanced in (False, True):
        clf = InitiationClassifier(1, 1, capacity=64, balanced=balanced)
        clf.add_examples(0, 0, obs, labels)
        clf.fit()
        logits[balanced] = (clf.logit(neg)[0, 0].item(), clf.logit(pos[:1])[0, 0].item())
        assert clf.config["balanced"] is balanced
    assert logits[False][0] > 0  # plain: the failure's start stays inside the set
    assert logits[True][0] < 0 < logits[True][1]  # balanced: out, the successes stay in


def _grid(n: int = 6) -> torch.Tensor:
    axis = (torch.arange(n, dtype=F64) + 0.5) / n
    return torch.cartesian_prod(axis, axis, axis, axis)


@pytest.mark.parametrize("centered", [False, True])
def test_initial_bias_lets_a_failure_carve_out_instead_of_emptying(centered):
    # One failed start state: from zero the fit says no everywhere (all features of s in
    # [0, 1] are >= 0); from a large intercept the failure removes only part of the set.
    start = torch.tensor([[0.2, 0.9, 0.5, 0.5]], dtype=F64)
    share = {}
    for bias in (0.0, 16.0):
        clf = InitiationClassifier(1, 1, initial_bias=bias, centered=centered)
        assert clf.logit(start).item() == bias
        clf.add_examples(0, 0, start, torch.zeros(1))
        clf.fit()
        assert clf.logit(start).item() < 0
        share[bias] = clf.contains_points(0, 0, _grid()).double().mean().item()
    assert share[0.0] == 0.0
    assert 0.2 < share[16.0] < 1.0


def test_centered_features_localise_a_negative():
    # Centred, the far point's features partly oppose the failure's, so it loses less.
    start = torch.tensor([[0.2, 0.9, 0.5, 0.5]], dtype=F64)
    far = torch.tensor([[0.9, 0.1, 0.5, 0.5]], dtype=F64)
    ratio = {}
    for centered in (False, True):
        clf = InitiationClassifier(1, 1, centered=centered, sweeps=1)
        clf.add_examples(0, 0, start, torch.zeros(1))
        clf.fit()
        ratio[centered] = clf.logit(far).item() / clf.logit(start).item()
    assert 0 < ratio[True] < 0.8 * ratio[False]


def test_reset_restores_the_initial_bias_and_config_round_trips():
    clf = InitiationClassifier(2, 2, initial_bias=3.0, centered=True)
    clf.add_examples(1, 0, rand((4, 4), 0), torch.zeros(4))
    clf.fit()
    assert clf.bias[1, 0].item() != 3.0
    clf.reset_slot(1, 0)
    assert clf.bias.tolist() == [[3.0, 3.0], [3.0, 3.0]]
    copy = clf.select_agents([1, 0])
    assert copy.config["initial_bias"] == 3.0 and copy.config["centered"] is True


def test_fit_runs_over_a_length_set_by_the_slots_own_count():
    clf = InitiationClassifier(1, 1, capacity=500)
    counts = torch.tensor([1, 8, 9, 100, 256, 257, 500])
    assert clf.fit_length(counts).tolist() == [8, 8, 16, 128, 256, 500, 500]
    # A few-example slot fitted beside a full one equals it fitted alone, bit for bit.
    together = InitiationClassifier(2, 2, capacity=300, balanced=True)
    alone = InitiationClassifier(1, 1, capacity=300, balanced=True)
    few, many = rand((3, 4), 1), rand((300, 4), 2)
    together.add_examples(0, 1, few, torch.tensor([1.0, 0.0, 1.0]))
    together.add_examples(1, 0, many, many[:, 0] < 0.5)
    alone.add_examples(0, 0, few, torch.tensor([1.0, 0.0, 1.0]))
    assert together.fit().sum().item() == 2 and alone.fit().sum().item() == 1
    assert torch.equal(together.weight[0, 1], alone.weight[0, 0])
    assert torch.equal(together.bias[0, 1], alone.bias[0, 0])


def test_distance_constraint_same_bits_alone_in_a_population_and_when_drawn():
    clf = InitiationClassifier(population=4, slots=2, capacity=64, distance=0.25)
    gen = torch.Generator().manual_seed(7)
    for p in range(4):
        x = torch.rand(64, 4, dtype=F64, generator=gen)
        clf.add_examples(p, 1, x, x[:, 0] < 0.6)
    clf.fit()
    clf.constrain(torch.ones(4, 2, dtype=torch.bool))
    points = torch.rand(300, 4, dtype=F64, generator=gen)
    for p in range(4):
        alone = clf.select_agents([p])
        drawn = clf.contains_points(p, 1, points)
        for i in range(0, 300, 7):
            obs = points[i : i + 1]
            together = clf.near_positive(obs.expand(4, 4).contiguous())[p, 1]
            assert bool(together) == bool(alone.near_positive(obs)[0, 1])
            member = clf.contains(obs.expand(4, 4).contiguous())[p, 1]
            assert bool(member) == bool(drawn[i])


@pytest.mark.parametrize("native", [False, True])
@pytest.mark.parametrize("replacement", ["reservoir", "ring"])
def test_keep_negatives_never_lets_positives_evict_failures(replacement, native):
    """A full store under keep_negatives: positives replace only positives, so every negative
    stays (without it, 2,000 positives leave about none of 5 negatives in a store of 50)."""
    from skillchain_torch.backends import initiation as native_initiation

    if native and not native_initiation.AVAILABLE:
        pytest.skip("compiled classifier not built")

    def run(keep: bool) -> InitiationClassifier:
        clf = InitiationClassifier(population=1, slots=1, capacity=50, sweeps=0,
                                   replacement=replacement, keep_negatives=keep)
        clf.set_native(native)
        x = rand((2105, 4), 1)
        clf.add_examples(0, 0, x[:20], torch.ones(20))           # a success
        for i in range(5):                                        # five failures, then
            clf.add_examples(0, 0, x[20 + i:21 + i], torch.zeros(1))
        for chunk in torch.split(torch.arange(25, 2105), 80):     # many more successes
            clf.add_examples(0, 0, x[chunk], torch.ones(len(chunk)))
        return clf

    kept = run(True)
    assert int((~kept.labels[0, 0]).sum()) == 5 and kept.count.item() == 50
    negatives = kept.examples[0, 0][~kept.labels[0, 0]]
    expected = rand((2105, 4), 1)[20:25]
    assert torch.equal(negatives[negatives[:, 0].argsort()], expected[expected[:, 0].argsort()])
    assert int((~run(False).labels[0, 0]).sum()) <= 1
    # a negative still replaces a positive once the store is full
    kept.add_examples(0, 0, rand((1, 4), 2), torch.zeros(1))
    assert int((~kept.labels[0, 0]).sum()) in (5, 6)  # 5 if its draw rejected it


def test_keep_negatives_same_stores_torch_and_compiled_with_mixed_batches():
    from skillchain_torch.backends import initiation as native_initiation

    if not native_initiation.AVAILABLE:
        pytest.skip("compiled classifier not built")
    compiled = compiled_stores_agree(30, keep_negatives=True)
    assert int((~compiled.labels).sum()) > 0
