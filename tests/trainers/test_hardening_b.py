"""Issue 17, part B: no silent wrong results from diverged learners, damaged checkpoints or
unsuitable option banks.

The command-line cases run the ``skillchain`` console script in a subprocess: each must exit
with status 2 and one ``skillchain train: error:`` line (no traceback), or run correctly.
"""

import dataclasses
import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from skillchain_torch.agents.given_options import load_given_options
from skillchain_torch.options import OptionBank, OptionStatus
from skillchain_torch.trainers import PopulationTrainer, TrainConfig
from skillchain_torch.trainers.config.cli import main
from skillchain_torch.trainers.loop.population import Diverged
from skillchain_torch.trainers.outputs.checkpoint import read_checkpoint

SCRIPT = Path(sys.executable).parent / "skillchain"
BOX = ["--map", "pinball_box", "--max-episode-steps", "300", "--quiet"]


def _train(*argv: str, timeout: int = 300) -> subprocess.CompletedProcess:
    return subprocess.run([str(SCRIPT), "train", *map(str, argv)], capture_output=True,
                          text=True, timeout=timeout, env={**os.environ, "COLUMNS": "100"})


def _refused(done: subprocess.CompletedProcess, *parts: str) -> str:
    """Exit status 2, no traceback, one error line holding ``parts``; returns that line."""
    assert "Traceback" not in done.stderr, done.stderr
    assert done.returncode == 2, done.stderr
    errors = [line for line in done.stderr.splitlines()
              if line.startswith("skillchain train: error:")]  # fmt: skip
    assert len(errors) == 1, done.stderr
    for part in parts:
        assert part in errors[0], errors[0]
    return errors[0]


def _bank(path: Path, population: int = 1, map: str | None = "pinball_box",
          status: OptionStatus = OptionStatus.LEARNING) -> Path:  # fmt: skip
    """A small bank: one option per agent, with ``status``, learned on ``map``."""
    bank = OptionBank.build(population, slots=2, order=1, capacity=16)
    bank.allocate(torch.ones(population, dtype=torch.bool), target_event=0, episode=0)
    if status != OptionStatus.GESTATING:
        bank.set_status(bank.live(), status)
    bank.map = map
    bank.save(path)
    return path


# ------------------------------------------------------------------ 1. divergence
@pytest.mark.slow
def test_diverged_skill_chaining_run_stops_and_names_agents_and_alpha(tmp_path):
    out = tmp_path / "run"
    done = _train("--agent", "skill-chaining", "--alpha", "1", "--runs", "2", "--episodes", "5",
                  "--max-episode-steps", "1000", "--checkpoint-every", "1", "--out", out,
                  "--quiet")  # fmt: skip
    _refused(done, "agents [0, 1] have non-finite weights", "the top-level Q-head of agents [0, 1]",
             "lower --alpha (now 1)", "partial_returns.npy")
    assert not (out / "returns.npy").exists()  # no plausible-looking finished run
    assert not list((out / "checkpoints").glob("*.pt"))  # no checkpoint of NaN weights
    returns = np.load(out / "partial_returns.npy")
    assert returns.shape == (2, 5) and np.isfinite(returns[:, 0]).all()
    assert np.isnan(returns[:, 1:]).all()
    info = json.loads((out / "diverged.json").read_text())
    assert info["agents"] == [0, 1] and info["episodes_done"] == [1, 1]


@pytest.mark.slow
def test_diverged_given_options_run_stops(tmp_path):
    bank = _bank(tmp_path / "bank.pt", map="pinball_simple_single")
    done = _train("--agent", "given-options", "--options", bank, "--alpha", "1e308",
                  "--runs", "2", "--episodes", "5", "--max-episode-steps", "1000",
                  "--out", tmp_path / "run", "--quiet")  # fmt: skip
    _refused(done, "agents [0, 1] have non-finite weights", "lower --alpha (now 1e+308)")


SC = TrainConfig(agent="skill-chaining", map="pinball_box", runs=2, episodes=4,
                 max_episode_steps=300, checkpoint_every=1, slots=2, option_alpha=0.0005)


class Poison:
    """post_episodes hook: put ``value`` into ``tensor(trainer)[agent]`` once the population
    has completed ``episode`` episodes."""

    def __init__(self, tensor, agent, episode, value=float("nan")):
        self.tensor, self.agent, self.episode, self.value = tensor, agent, episode, value

    def __call__(self, trainer, batch):
        if batch.population_episode == self.episode:
            self.tensor(trainer)[self.agent].view(-1)[0] = self.value


def test_frozen_options_point_at_the_top_level_step_size(tmp_path):
    """With the default ``option_alpha = 0`` option heads only copy the top level's, so a
    non-finite option head is the top level's divergence: the advice names ``--alpha``."""
    cfg = dataclasses.replace(SC, option_alpha=0.0)
    trainer = PopulationTrainer(cfg, out_dir=tmp_path)
    trainer.register_op("post_episodes",
                        Poison(lambda t: t.agent.bank.q_head.weight, 1, 2, float("nan")))
    with pytest.raises(Diverged) as info:
        trainer.train()
    assert "they only copy the top-level Q-head: lower --alpha (now 0.001)" in str(info.value)
    assert "--option-alpha" not in str(info.value)


@pytest.mark.parametrize(
    ("tensor", "learner", "advice"),
    [
        (lambda t: t.agent.bank.q_head.weight, "the option Q-heads of agents [1]",
         "lower --option-alpha (now 0.0005)"),
        (lambda t: t.agent.bank.classifier.bias, "the initiation classifiers of agents [1]",
         "not a run parameter"),
        (lambda t: t.agent.q_head.weight, "the top-level Q-head of agents [1]", "--alpha"),
    ],
)
def test_no_checkpoint_of_diverged_weights(tmp_path, tensor, learner, advice):
    """Weights poisoned after episode 2: the checkpoint of episode 2 is refused, the one of
    episode 1 is kept, and the returns so far are saved."""
    trainer = PopulationTrainer(SC, out_dir=tmp_path)
    trainer.register_op("post_episodes", Poison(tensor, 1, 2, float("inf")))
    with pytest.raises(Diverged) as info:
        trainer.train()
    message = str(info.value)
    assert learner in message and advice in message and "\n" not in message
    assert f"last good checkpoint {tmp_path / 'checkpoints' / 'ckpt_000001.pt'}" in message
    assert info.value.agents == [1]
    assert sorted(p.name for p in (tmp_path / "checkpoints").iterdir()) == ["ckpt_000001.pt"]
    kept = read_checkpoint(tmp_path / "checkpoints" / "ckpt_000001.pt")
    assert torch.isfinite(kept["agent"]["bank"]["q_head.weight"]).all()
    partial = np.load(tmp_path / "partial_returns.npy")
    assert np.isfinite(partial[:, :2]).all() and np.isnan(partial[:, 3]).all()
    with pytest.raises(Diverged):  # a diverged trainer does not go on
        trainer.train()


def test_divergence_found_at_the_episode_end_without_checkpoints():
    cfg = TrainConfig(**{**SC.to_dict(), "checkpoint_every": 0})
    trainer = PopulationTrainer(cfg)
    trainer.register_op("post_episodes", Poison(lambda t: t.agent.bank.q_head.weight, 0, 1))
    with pytest.raises(Diverged, match=r"agents \[0\] have non-finite weights \(NaN or "
                                       r"infinite\) after 2 completed episodes: the option "
                                       r"Q-heads of agents \[0\]: lower --option-alpha"):
        trainer.train()
    assert trainer.episodes_done.tolist()[0] == 2


def test_flat_agents_own_check_names_the_parameter(tmp_path):
    """The flat agent finds NaN weights itself, mid-episode (every 64 decisions): the trainer
    turns its FloatingPointError into the same report."""
    cfg = TrainConfig(runs=2, episodes=3, max_episode_steps=1000, alpha=1.0)
    trainer = PopulationTrainer(cfg, out_dir=tmp_path)
    with pytest.raises(Diverged, match=r"after 0 completed episodes: the top-level Q-head of "
                                       r"agents \[0, 1\]: lower --alpha \(now 1\)"):
        trainer.train()
    assert (tmp_path / "diverged.json").is_file()


# ------------------------------------------------------------------ 2. checkpoints
def _flip_returns(path: Path) -> None:
    data = bytearray(path.read_bytes())
    at = data.find(torch.load(path, weights_only=True)["trainer"]["returns"].numpy().tobytes())
    assert at > 0
    data[at + 3] ^= 0x40
    path.write_bytes(bytes(data))


@pytest.mark.slow
def test_resume_of_an_altered_checkpoint_takes_the_previous_one(tmp_path):
    out = tmp_path / "run"
    assert main(["train", "--runs", "2", "--episodes", "3", "--checkpoint-every", "1",
                 "--out", str(out), *BOX]) == 0  # fmt: skip
    reference = np.load(out / "returns.npy")
    latest = out / "checkpoints" / "ckpt_000003.pt"
    _flip_returns(latest)
    done = _train("--resume", out)
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert f"{latest}: checksum mismatch" in done.stderr
    assert "resuming from the previous good checkpoint ckpt_000002.pt" in done.stderr
    assert np.array_equal(np.load(out / "returns.npy"), reference)
    assert (out / "checkpoints" / "ckpt_000003.pt.damaged").is_file()
    read_checkpoint(latest)  # written again, and verified


# ------------------------------------------------------------------ 3. option banks
def test_bank_of_another_map_is_refused(tmp_path):
    bank = _bank(tmp_path / "hard.pt", map="pinball_hard_single")
    done = _train("--agent", "given-options", "--options", bank, "--out", tmp_path / "run")
    _refused(done, f"{bank}: the options were learned with map = 'pinball_hard_single', but "
                   "this run has map = 'pinball_simple_single' (--map pinball_simple_single)")
    assert not (tmp_path / "run").exists()


def test_bank_with_nan_weights_is_refused(tmp_path):
    bank = OptionBank.build(1, slots=2, order=1, capacity=16)
    bank.q_head.weight[0, 1, 2, 3] = float("nan")
    bank.save(tmp_path / "nan.pt")
    done = _train("--agent", "given-options", "--options", tmp_path / "nan.pt",
                  "--out", tmp_path / "run")  # fmt: skip
    _refused(done, "nan.pt: tensor 'q_head.weight' holds 1 NaN or infinite values (agents [0])")


@pytest.mark.slow
def test_all_gestating_options_warn(tmp_path):
    bank = _bank(tmp_path / "young.pt", status=OptionStatus.GESTATING)
    done = _train("--agent", "given-options", "--options", bank, "--runs", "2",
                  "--episodes", "1", "--out", tmp_path / "run", *BOX)  # fmt: skip
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    assert ("the options of saved agent(s) [0] are all still gestating: 1 option(s) dropped "
            "(never executed, no initiation set yet); 2 of this run's 2 agents start with 0 "
            "options") in done.stderr


def test_given_options_checks_what_it_can(tmp_path, caplog):
    legacy = OptionBank.build(2, slots=2, order=1, capacity=16)
    payload = legacy._payload()
    del payload["environment"], payload["features"]
    torch.save(payload, tmp_path / "old.pt")
    with caplog.at_level(logging.WARNING):
        bank = load_given_options(tmp_path / "old.pt", 3, map="pinball_box", agent=None)
    assert bank.population == 3
    assert "records no map" in caplog.text and "cannot check" in caplog.text
    assert "holds 2 agents and this run has 3" in caplog.text
    assert "saved agent(s) [0, 1] hold no options; 3 of this run's 3 agents" in caplog.text
    good = _bank(tmp_path / "good.pt", population=2)
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        bank = load_given_options(good, 2, map="pinball_box", agent=1)
    assert caplog.text == "" and bank.status.tolist() == [[3, 0], [3, 0]]  # LEARNED


def _bad_options(tmp_path: Path, kind: str) -> tuple[Path, list[str], str]:
    """An --options file of ``kind``, the extra arguments, and what the error must say."""
    path = tmp_path / f"{kind}.pt"
    if kind == "empty":
        path.write_bytes(b"")
        return path, [], "(the file is empty)"
    if kind == "text":
        path.write_text("options: none\n")
        return path, [], "(not a torch file: it starts with b'opti')"
    if kind == "random":
        path.write_bytes(bytes(np.random.default_rng(0).integers(0, 256, 512, np.uint8)))
        return path, [], "not a torch file"
    if kind == "truncated":
        good = _bank(tmp_path / "good.pt").read_bytes()
        path.write_bytes(good[: len(good) // 2])
        return path, [], "(a truncated or damaged torch file"
    if kind == "foreign":
        torch.save({"a": 1}, path)
        return path, [], "not an OptionBank file (format 'skillchain_torch.OptionBank' expected"
    if kind == "checkpoint":
        PopulationTrainer(TrainConfig(runs=1, episodes=1, max_episode_steps=5)).save_checkpoint(
            path)
        return path, [], "it is a training checkpoint"
    if kind == "version":
        _bank(path)
        payload = torch.load(path, weights_only=True)
        payload["version"] = 7
        torch.save(payload, path)
        return path, [], "OptionBank format version 7, this library reads version 1"
    assert kind == "agent"
    return _bank(path), ["--options-agent", "5"], \
        "--options-agent 5: " + str(path) + " holds 1 agent, so expected 0..0 or 'each'"


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["empty", "text", "random", "truncated", "foreign",
                                  "checkpoint", "version", "agent"])
def test_bad_options_file_gives_one_line(tmp_path, kind):
    path, extra, message = _bad_options(tmp_path, kind)
    done = _train("--agent", "given-options", "--options", path, *extra,
                  "--out", tmp_path / "run", *BOX)  # fmt: skip
    line = _refused(done, str(path), message)
    assert len(line) < 400
    assert not (tmp_path / "run").exists()


def test_a_skill_chaining_run_saves_its_map_with_its_options(tmp_path):
    cfg = TrainConfig(**{**SC.to_dict(), "episodes": 1, "checkpoint_every": 0})
    trainer = PopulationTrainer(cfg).train()
    trainer.agent.bank.save(tmp_path / "options.pt")
    bank = OptionBank.load(tmp_path / "options.pt")
    assert bank.map == "pinball_box" and not bank.legacy
    with pytest.raises(ValueError, match="learned with map = 'pinball_box'"):
        load_given_options(tmp_path / "options.pt", 1, map="pinball_simple_single")


def test_options_whose_sets_are_all_empty_warn(tmp_path, caplog):
    """The paper preset's hard banks hold executable options whose sets were refitted on
    timeouts until they hold nothing: their given agents learn as flat ones, silently."""
    bank = OptionBank.load(_bank(tmp_path / "three.pt", population=3))
    clf = bank.classifier
    clf.trained[1, 0] = True  # agent 1's one option, fitted to nothing: logit -1 everywhere
    clf.weight[1, 0] = 0.0
    clf.bias[1, 0] = -1.0
    bank.save(tmp_path / "dead.pt")
    with caplog.at_level(logging.WARNING):
        load_given_options(tmp_path / "dead.pt", 3, map="pinball_box", agent=None)
    assert ("no option of saved agent(s) [1] holds a state of the Figure-5 probe grid (every "
            "initiation set is empty); 1 of this run's 3 agents will likely never take an "
            "option") in caplog.text, caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        load_given_options(tmp_path / "dead.pt", 2, map="pinball_box", agent=0)
    assert caplog.text == ""  # agent 0's set is true everywhere


def test_many_dead_agents_are_named_in_one_short_line(tmp_path, caplog):
    bank = OptionBank.load(_bank(tmp_path / "many.pt", population=12))
    bank.classifier.trained[:, 0] = True  # every agent's one option fitted to nothing
    bank.classifier.weight[:, 0] = 0.0
    bank.classifier.bias[:, 0] = -1.0
    bank.save(tmp_path / "dead.pt")
    with caplog.at_level(logging.WARNING):
        load_given_options(tmp_path / "dead.pt", 12, map="pinball_box", agent=None)
    assert "saved agent(s) [0, 1, 2, 3, 4, 5, 6, 7, ...] (12 in all) holds" in caplog.text
    assert "12 of this run's 12 agents will likely never take an option" in caplog.text
