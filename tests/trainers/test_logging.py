"""TensorBoard scalars through TorchRL's logger, the progress bar, the figure, the summary."""

import doctest
import importlib
import io

import numpy as np
import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from skillchain_torch.trainers import PopulationTrainer, ProgressBar, TensorBoardHook, TrainConfig
from skillchain_torch.trainers.outputs.logging import population_interval
from skillchain_torch.trainers.outputs.plots import learning_curve, save_learning_curve
from skillchain_torch.trainers.study.summary import summarize


def test_doctests():
    for name in ("outputs.logging", "outputs.progress"):
        module = importlib.import_module(f"skillchain_torch.trainers.{name}")
        assert doctest.testmod(module, optionflags=doctest.ELLIPSIS).failed == 0


@pytest.fixture(scope="module")
def logged_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("tb")
    cfg = TrainConfig(map="pinball_box", runs=3, episodes=3, seed=0, max_episode_steps=200)
    trainer = PopulationTrainer(cfg, out_dir=out)
    hook = TensorBoardHook.for_run(trainer, out)
    hook.register(trainer)
    stream = io.StringIO()
    ProgressBar(file=stream, min_interval=0).register(trainer)
    trainer.train()
    hook.close()
    events = EventAccumulator(str(out / "tb" / "flat_pinball_box_P3_seed0"))
    events.Reload()
    return trainer, events, stream.getvalue()


def test_scalars(logged_run):
    trainer, events, _ = logged_run
    tags = set(events.Tags()["scalars"])
    for p in range(3):
        assert {f"agent_{p}/return", f"agent_{p}/length"} <= tags
        returns = [e.value for e in events.Scalars(f"agent_{p}/return")]
        assert [e.step for e in events.Scalars(f"agent_{p}/return")] == [1, 2, 3]
        assert np.allclose(returns, trainer.returns[p])
    mean = events.Scalars("population/return_mean")
    low = events.Scalars("population/return_ci_low")
    high = events.Scalars("population/return_ci_high")
    assert [e.step for e in mean] == [1, 2, 3]
    for e in range(3):
        m, lo, hi = population_interval(trainer.returns[:, e])
        assert np.isclose(mean[e].value, m) and np.isclose(low[e].value, lo)
        assert np.isclose(high[e].value, hi)
    assert "perf/agent_steps_per_second" in tags
    assert "config/text_summary" in events.Tags()["tensors"]  # the text summary


def test_progress_bar(logged_run):
    _, _, text = logged_run
    assert "9/9" in text and "mean return of the last" in text and "agent steps/s" in text


def test_population_interval_and_curve():
    mean, low, high = population_interval([10.0])
    assert mean == low == high == 10.0
    r = np.array([[1.0, 2.0], [3.0, np.nan]])
    m, lo, hi = learning_curve(r)
    assert m.tolist() == [2.0, 2.0] and lo[1] == hi[1] == 2.0
    # Student's t(1) = 12.706, not the normal's 1.96: two runs give a wide interval
    assert np.isclose(hi[0] - m[0], 12.7062047 * np.std([1.0, 3.0], ddof=1) / np.sqrt(2))
    m, lo, hi = population_interval([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0])
    assert np.isclose(hi - m, 2.2621572 * np.std(np.arange(1, 11), ddof=1) / np.sqrt(10))


def test_save_learning_curve(tmp_path):
    path = save_learning_curve(np.random.default_rng(0).normal(size=(4, 30)), tmp_path / "c.png")
    assert path.read_bytes()[:4] == b"\x89PNG"


def test_summary_windows():
    returns = np.arange(2 * 250, dtype=np.float64).reshape(2, 250)
    lengths = np.ones((2, 250), dtype=np.int64)
    table = summarize(returns, lengths)
    assert [w["episodes"] for w in table["windows"]] == [
        "1-10", "11-25", "26-50", "51-100", "101-150", "151-200", "201-250"]
    first = table["windows"][0]
    assert first["return_mean"] == np.mean([4.5, 254.5])
    assert np.isclose(first["return_se"], 125.0)
    assert table["steps_per_run"] == {"mean": 250.0, "min": 250, "max": 250}
