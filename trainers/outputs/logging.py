"""TensorBoard logging of a population run through TorchRL's ``TensorboardLogger``.

Written once per completed episode, never per step, so logging stays off the hot path:

* ``agent_{p}/return`` and ``agent_{p}/length`` at step = episode number (1-based);
* ``population/return_mean``, ``population/return_ci_low``, ``population/return_ci_high`` (mean
  +- t(n - 1) sd / sqrt(n) over the agents: Student's t, sample sd) and
  ``population/length_mean``, written when the slowest agent completes that episode (every
  agent has then completed it);
* ``perf/agent_steps_per_second`` and ``perf/active_agents`` at the same moments;
* the hyperparameters (``log_hparams``) and a text summary of the config at the start;
* for agents with an option bank, the option statistics and initiation-set images of
  :class:`~.option_monitor.OptionMonitor` (registered by :meth:`TensorBoardHook.register`).

Example:
    >>> import tempfile
    >>> from skillchain_torch.trainers import PopulationTrainer, TrainConfig
    >>> trainer = PopulationTrainer(TrainConfig(runs=2, episodes=1, max_episode_steps=3))
    >>> TensorBoardHook.for_run(trainer, tempfile.mkdtemp()).register(trainer)
    >>> _ = trainer.train()
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from torch.utils.tensorboard.summary import hparams
from torchrl.record.loggers import TensorboardLogger

from skillchain_torch.trainers.loop.user_agent import agent_label, run_record
from skillchain_torch.trainers.outputs.plots import t95
from skillchain_torch.trainers.outputs.timed import TimedHook

__all__ = ["TensorBoardHook", "population_interval", "experiment_name", "log_population_arrays"]


def population_interval(values) -> tuple[float, float, float]:
    """``(mean, low, high)``: mean +- t(n - 1) * sd / sqrt(n), Student's 95% interval (sample
    sd; 0 width when n == 1).

    Example:
        >>> population_interval([1.0, 2.0, 3.0])
        (2.0, -0.484..., 4.484...)
    """
    x = np.asarray(values, dtype=np.float64)
    mean = float(x.mean())
    half = t95(x.size) * float(x.std(ddof=1)) / math.sqrt(x.size) if x.size > 1 else 0.0
    return mean, mean - half, mean + half


def experiment_name(config, agent: str | None = None) -> str:
    """The run's folder under ``tb/``: agent (``agent``, else the config's kind), env, size,
    seed."""
    name = config.env_name.replace(":", "-").replace("/", "-")
    return f"{agent or config.agent}_{name}_P{config.runs}_seed{config.seed}"


def log_config(logger, config: dict) -> None:
    """The hyperparameters and a text table of ``config`` (a run's recorded fields,
    :func:`.user_agent.run_record`), once, at a run's start."""
    values = {k: v if isinstance(v, (bool, int, float, str)) else str(v)
              for k, v in config.items()}  # None and lists as text, as TensorBoard shows them
    # TorchRL's log_hparams calls SummaryWriter.add_hparams, which writes into a new
    # timestamped run beside this one (an empty run in TensorBoard's list): the same summary
    # goes into this run's own writer instead.
    writer = logger.experiment._get_file_writer()
    for summary in hparams(values, metric_dict={}):
        writer.add_summary(summary)
    rows = "\n".join(f"| {k} | {v} |" for k, v in config.items())
    logger.experiment.add_text("config", "| field | value |\n|---|---|\n" + rows, 0)


def log_population_arrays(logger, config, returns, lengths, n_options=None,
                          per_agent: bool = True) -> None:
    """After the fact, the scalars :class:`TensorBoardHook` writes during a run, from its
    arrays ``[P, E]`` (a sharded run's merged blocks): the config, ``agent_{p}/return`` and
    ``length``, ``population/*`` per episode, and with ``n_options`` ``agent_{p}/options`` and
    ``discovery/options_mean``/``_max``. (``perf/*`` needs the run's clock: not written.)

    Example:
        >>> import tempfile, numpy as np
        >>> from skillchain_torch.trainers import TrainConfig
        >>> logger = TensorboardLogger("x", log_dir=tempfile.mkdtemp())
        >>> log_population_arrays(logger, TrainConfig(), np.ones((2, 3)), np.ones((2, 3), int))
    """
    log = logger.log_scalar
    log_config(logger, config.to_dict())
    P, E = returns.shape
    if per_agent:
        for p in range(P):
            for e in range(E):
                log(f"agent_{p}/return", float(returns[p, e]), step=e + 1)
                log(f"agent_{p}/length", int(lengths[p, e]), step=e + 1)
                if n_options is not None:
                    log(f"agent_{p}/options", float(n_options[p, e]), step=e + 1)
    for e in range(E):
        mean, low, high = population_interval(returns[:, e])
        log("population/return_mean", mean, step=e + 1)
        log("population/return_ci_low", low, step=e + 1)
        log("population/return_ci_high", high, step=e + 1)
        log("population/length_mean", float(lengths[:, e].mean()), step=e + 1)
        if n_options is not None:
            log("discovery/options_mean", float(n_options[:, e].mean()), step=e + 1)
            log("discovery/options_max", float(n_options[:, e].max()), step=e + 1)
    logger.experiment.flush()


class TensorBoardHook(TimedHook):
    """Trainer hook writing per-episode scalars to a TorchRL ``TensorboardLogger``.

    Args:
        logger: the logger (``exp_name``, ``log_dir``); see :meth:`for_run`.
        per_agent: also write every agent's return and length (P scalars per episode).
        options: when the trainer's agent has an option bank, :meth:`register` also registers
            an :class:`~.option_monitor.OptionMonitor` on this logger (``option_monitor``).
    """

    def __init__(self, logger: TensorboardLogger, per_agent: bool = True, options: bool = True):
        self.logger = logger
        self.per_agent = per_agent
        self.options = options
        self.option_monitor = None
        self._last = None  # (elapsed, agent_steps) at the previous population point
        self.seconds = 0.0  # wall time writing the scalars (recorded in run_info.json)
        # Read from the collector's batches: agent steps taken inside an option, and all
        # agent steps, since the previous population point.
        self._option_steps, self._steps = 0, 0

    @classmethod
    def for_run(cls, trainer, out_dir: str | Path, **kwargs) -> TensorBoardHook:
        """A hook logging to ``out_dir/tb/<experiment name>``."""
        log_dir = str(Path(out_dir) / "tb")
        logger = TensorboardLogger(experiment_name(trainer.config, agent_label(trainer)),
                                   log_dir=log_dir)  # fmt: skip
        return cls(logger, **kwargs)

    def register(self, trainer, name: str = "tensorboard") -> None:
        trainer.register_op("pre_train", self.pre_train, name=name)
        trainer.register_op("post_episodes", self.post_episodes, name=name)
        trainer.register_op("post_train", self.post_train, name=name)
        if self.options and getattr(trainer.agent, "bank", None) is not None:
            from skillchain_torch.trainers.outputs.option_monitor import OptionMonitor

            self.option_monitor = OptionMonitor(self.logger)
            self.option_monitor.register(trainer, name=f"{name}_options")

    def pre_train(self, trainer) -> None:
        self._last = (trainer.wall_time, trainer.agent_steps)
        if trainer.global_step > 0:
            return  # resumed: the hyperparameters are already logged
        log_config(self.logger, run_record(trainer))

    def _post_episodes(self, trainer, batch) -> None:
        log = self.logger.log_scalar
        transitions = batch.transitions
        if transitions is not None and "option" in transitions.keys():
            self._option_steps += int((transitions["option"] >= 0).sum())
            self._steps += transitions["option"].numel()
        if self.per_agent:
            for p, e, r, n in zip(batch.agents, batch.episodes, batch.returns, batch.lengths):
                log(f"agent_{p}/return", r, step=e + 1)
                log(f"agent_{p}/length", n, step=e + 1)
        episode = batch.population_episode
        if episode is None:
            return
        mean, low, high = population_interval(trainer.returns[:, episode - 1])
        log("population/return_mean", mean, step=episode)
        log("population/return_ci_low", low, step=episode)
        log("population/return_ci_high", high, step=episode)
        log("population/length_mean", float(trainer.lengths[:, episode - 1].mean()), step=episode)
        elapsed = trainer.wall_time
        last_elapsed, last_steps = self._last or (0.0, 0)
        if elapsed > last_elapsed:
            rate = (trainer.agent_steps - last_steps) / (elapsed - last_elapsed)
            log("perf/agent_steps_per_second", rate, step=episode)
        log("perf/active_agents", trainer.num_active, step=episode)
        self._last = (elapsed, trainer.agent_steps)
        if self._steps:  # the share of agent steps an option took, since the last point
            log("population/option_step_share", self._option_steps / self._steps, step=episode)
            self._option_steps, self._steps = 0, 0

    def post_train(self, trainer) -> None:
        self.logger.experiment.flush()

    def close(self) -> None:
        self.logger.experiment.close()
