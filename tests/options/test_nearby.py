"""within_any and contains_points: the grid shortcut answers what the dense matrix answers."""

import doctest

import pytest
import torch

from skillchain_torch.invariant import rowwise_dot
from skillchain_torch.options import InitiationClassifier, nearby
from skillchain_torch.options.nearby import within_any


def dense(points, examples, distance):
    d = torch.cdist(points, examples, compute_mode="donot_use_mm_for_euclid_dist")
    return (d <= distance).any(-1)


def boundary_case(seed: int, d: int, n: int = 800, m: int = 300, spread: float = 1.3):
    """Random points, a third of them at distance 0.1 +- a few ulps from an example."""
    g = torch.Generator().manual_seed(seed)
    examples = torch.rand(m, d, generator=g, dtype=torch.float64) * spread
    points = torch.rand(n, d, generator=g, dtype=torch.float64) * spread
    k = n // 3
    pick = torch.randint(0, m, (k,), generator=g)
    v = torch.randn(k, d, generator=g, dtype=torch.float64)
    v = v / v.norm(dim=-1, keepdim=True)
    ulps = torch.randint(-4, 5, (k, 1), generator=g).double() * 2.0**-52
    points[:k] = examples[pick] + v * 0.1 * (1 + ulps)
    return points, examples


def test_doctests():
    assert doctest.testmod(nearby).failed == 0


@pytest.mark.parametrize("d", [2, 3, 4])
@pytest.mark.parametrize("seed", range(8))
def test_equals_dense_at_the_boundary(seed, d):
    points, examples = boundary_case(seed, d, spread=0.3 if seed % 2 else 1.3)
    assert torch.equal(within_any(points, examples, 0.1), dense(points, examples, 0.1))


def test_search_path_equals_dense(monkeypatch):
    monkeypatch.setattr(nearby, "_TABLE_CELLS", 0)  # no table: searchsorted on the keys
    points, examples = boundary_case(1, 4)
    assert torch.equal(within_any(points, examples, 0.1), dense(points, examples, 0.1))


def test_fallbacks_and_empty():
    points, examples = boundary_case(2, 4)
    points[5] = float("nan")
    points[6] = float("inf")
    assert torch.equal(within_any(points, examples, 0.1), dense(points, examples, 0.1))
    far = torch.tensor([[1e300, 0.0, 0.0, 0.0]], dtype=torch.float64)  # keys would overflow
    assert torch.equal(within_any(torch.cat([points[:5], far]), examples, 0.1),
                       dense(torch.cat([points[:5], far]), examples, 0.1))
    assert within_any(points[:0], examples, 0.1).shape == (0,)
    assert not within_any(points, examples[:0], 0.1).any()
    crowded = torch.zeros(50, 4, dtype=torch.float64)  # every pair a neighbour: dense
    assert within_any(crowded, crowded, 0.1).all()


def reference_contains_points(clf, p, k, obs):
    """contains_points before the shortcut: the dense distance matrix on every point."""
    w, b = clf.weight[p, k], clf.bias[p, k]
    count = int(clf.count[p, k])
    positives = clf.examples[p, k, :count][clf.labels[p, k, :count]]
    if bool(clf.trained[p, k]):
        member = (rowwise_dot(clf.phi(obs), w[None, :]) + b) > 0
    else:
        member = torch.ones(obs.shape[0], dtype=torch.bool)
    if bool(clf.constrained[p, k]):
        near = (clf._within(obs, positives).any(-1) if positives.shape[0]
                else torch.zeros_like(member))
        member = member & near
    return member


@pytest.mark.parametrize("dims", [None, (0, 1)])
def test_contains_points_equals_the_dense_rule(dims):
    # A crafted slot: a trained logistic set (x + y < 1.1), constrained to 0.1 of 60
    # positives on a diagonal band, probed at points on and around the band.
    clf = InitiationClassifier(population=2, slots=2, capacity=80, distance_dims=dims)
    g = torch.Generator().manual_seed(0)
    t = torch.rand(80, 1, generator=g, dtype=torch.float64)
    band = torch.cat([t, 1 - t, torch.rand(80, 2, generator=g, dtype=torch.float64)], -1)
    labels = torch.arange(80) % 4 != 0  # 60 positives, 20 negatives
    clf.add_examples(1, 1, band, labels)
    with torch.no_grad():
        clf.weight[1, 1].zero_()
        clf.weight[1, 1, 1] = clf.weight[1, 1, 2] = -1.0
        clf.bias[1, 1] = 1.1
        clf.trained[1, 1] = True
        clf.constrained[1, 1] = True
    probe = torch.rand(5000, 4, generator=g, dtype=torch.float64)
    probe[:2000] = band[torch.randint(0, 80, (2000,), generator=g)] + 0.07 * torch.randn(
        2000, 4, generator=g, dtype=torch.float64)
    got = clf.contains_points(1, 1, probe)
    want = reference_contains_points(clf, 1, 1, probe)
    assert 0 < int(got.sum()) < 5000 and torch.equal(got, want)
    with torch.no_grad():  # untrained but constrained: the distance test alone
        clf.trained[1, 1] = False
    assert torch.equal(clf.contains_points(1, 1, probe),
                       reference_contains_points(clf, 1, 1, probe))
