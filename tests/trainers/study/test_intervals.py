"""Student-t intervals without SciPy: quantiles against published values, intervals against
SciPy's (numbers computed once with scipy 1.17 and written here)."""

import doctest
import math

import numpy as np
import pytest

from skillchain_torch.trainers.study import intervals
from skillchain_torch.trainers.study.intervals import diff_ci, mean_ci, t_quantile, welch_df

# scipy.stats.t.ppf(0.975, df): the two-sided 95% quantiles of every t table
T975 = {1: 12.706204736174694, 2: 4.302652729749462, 5: 2.5705818356363146,
        9: 2.262157162798205, 10: 2.228138851986274, 29: 2.045229642132703,
        30: 2.0422724563012378, 99: 1.9842169515864174, 120: 1.9799304050824402,
        1000: 1.9623390808264083}  # fmt: skip
# (q, df, scipy.stats.t.ppf(q, df)): other levels and the fractional df of Welch's intervals
OTHERS = [(0.95, 10, 1.8124611228116756), (0.975, 4.615384615384615, 2.6363688430325816),
          (0.995, 2.5, 7.163728138948783), (0.975, 0.3, 6582.0356994007525),
          (0.5000001, 1e6, 2.5066288999687953e-07)]  # fmt: skip
X = [6200.0, 5400.0, 7100.0, 6900.0, 5800.0, 6600.0, 7300.0, 6100.0]
Y = [5200.0, 6100.0, 4300.0, 5900.0, 5000.0]


def test_doctest():
    assert doctest.testmod(intervals).failed == 0


@pytest.mark.parametrize(("df", "expected"), sorted(T975.items()))
def test_t_quantile_matches_the_tables(df, expected):
    assert t_quantile(0.975, df) == pytest.approx(expected, rel=1e-11)
    assert t_quantile(0.025, df) == pytest.approx(-expected, rel=1e-11)


@pytest.mark.parametrize(("q", "df", "expected"), OTHERS)
def test_t_quantile_other_levels_and_fractional_df(q, df, expected):
    assert t_quantile(q, df) == pytest.approx(expected, rel=1e-8)


def test_t_quantile_tends_to_the_normal():
    values = [t_quantile(0.975, df) for df in (1, 3, 10, 100, 10_000)]
    assert values == sorted(values, reverse=True)
    assert t_quantile(0.975, math.inf) == pytest.approx(1.959963984540054, rel=1e-14)
    assert t_quantile(0.975, 10_000) == pytest.approx(1.960201239890626, rel=1e-11)
    assert t_quantile(0.5, 7) == 0.0


@pytest.mark.parametrize(("q", "df"), [(0.0, 5), (1.0, 5), (1.2, 5), (0.975, 0), (0.975, -1)])
def test_t_quantile_refuses_what_is_not_a_quantile(q, df):
    with pytest.raises(ValueError, match="probability|degrees of freedom"):
        t_quantile(q, df)


def test_mean_ci_is_scipys_t_interval():
    mean, half = mean_ci(X)
    assert mean == 6425.0
    assert (mean - half, mean + half) == pytest.approx((5870.896764671192, 6979.103235328808),
                                                       rel=1e-12)
    mean, half = mean_ci(X, level=0.9)
    assert mean + half == pytest.approx(6868.957273109241, rel=1e-12)
    assert 1.96 * np.std(X, ddof=1) / math.sqrt(len(X)) < mean_ci(X)[1]  # wider than z


def test_diff_ci_is_welchs_interval():
    d, half = diff_ci(X, Y)
    assert d == 6425.0 - 5300.0
    assert (d - half, d + half) == pytest.approx((203.3295028649071, 2046.6704971350928),
                                                 rel=1e-12)
    assert welch_df(X, Y) == pytest.approx(8.023692902420748, rel=1e-12)


def test_welch_df_limits():
    rng = np.random.default_rng(0)
    x = rng.normal(size=12)
    assert welch_df(x, np.full(5, 3.0)) == pytest.approx(11)  # all the variance is x's
    assert welch_df(x, x + 1.0) == pytest.approx(22)  # equal sizes and variances: 2n - 2
    assert welch_df([1.0, 1.0], [2.0, 2.0]) == math.inf


def test_degenerate_samples():
    assert math.isnan(mean_ci([4.0])[1]) and mean_ci([4.0])[0] == 4.0
    assert math.isnan(diff_ci([4.0], [1.0, 2.0])[1])
    assert diff_ci([1.0, 1.0], [2.0, 2.0]) == (-1.0, 0.0)
