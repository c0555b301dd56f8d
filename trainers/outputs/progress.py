"""A tqdm progress bar over agent-episodes, updated when episodes end (never per step).

Total = runs * episodes; the postfix shows the mean return of the last completed episodes
(up to ``window``), agent steps per second and the number of agents still training.

Example:
    >>> from skillchain_torch.trainers import PopulationTrainer, TrainConfig
    >>> trainer = PopulationTrainer(TrainConfig(runs=2, episodes=1, max_episode_steps=3))
    >>> ProgressBar(disable=True).register(trainer)
    >>> trainer.train().finished
    True
"""

from __future__ import annotations

from collections import deque

from tqdm.auto import tqdm

from skillchain_torch.trainers.loop.user_agent import agent_label

__all__ = ["ProgressBar"]


class ProgressBar:
    """Trainer hook driving a tqdm bar.

    Args:
        window: number of most recent episodes in the postfix's mean return.
        min_interval: seconds between postfix refreshes.
        **tqdm_kwargs: passed to ``tqdm`` (e.g. ``disable=True``, ``file=...``).
    """

    def __init__(self, window: int = 100, min_interval: float = 0.5, **tqdm_kwargs):
        self.recent = deque(maxlen=window)
        self.min_interval = min_interval
        self.tqdm_kwargs = tqdm_kwargs
        self.bar = None
        self._last_refresh = -float("inf")

    def register(self, trainer, name: str = "progress") -> None:
        trainer.register_op("pre_train", self.pre_train, name=name)
        trainer.register_op("post_episodes", self.post_episodes, name=name)
        trainer.register_op("post_train", self.post_train, name=name)

    def pre_train(self, trainer) -> None:
        if self.bar is not None:
            return
        cfg = trainer.config
        done = int(trainer.episodes_done.sum())
        self.bar = tqdm(total=cfg.runs * cfg.episodes, initial=done, unit="ep",
                        desc=f"{agent_label(trainer)} {cfg.env_name}", dynamic_ncols=True,
                        **self.tqdm_kwargs)  # fmt: skip

    def post_episodes(self, trainer, batch) -> None:
        self.recent.extend(batch.returns)
        self.bar.update(len(batch.returns))
        now = trainer.wall_time
        if now - self._last_refresh >= self.min_interval:
            self._last_refresh = now
            mean = sum(self.recent) / len(self.recent)
            # Labelled in words: what the return is a mean of, and what the rates count.
            self.bar.set_postfix_str(
                f"mean return of the last {len(self.recent)} episodes {mean:,.0f}, "
                f"{trainer.steps_per_second():,.0f} agent steps/s, "
                f"{trainer.num_active} agents training", refresh=False)

    def post_train(self, trainer) -> None:
        self.close()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
