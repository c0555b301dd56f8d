"""``TimedHook``: a trainer hook that adds the wall time of its per-episode work to ``seconds``,
which ``run_info.json`` reports (where a run's time went: monitoring against training).

Example:
    >>> class Hook(TimedHook):
    ...     def _post_episodes(self, trainer, batch):
    ...         self.calls = getattr(self, "calls", 0) + 1
    >>> hook = Hook()
    >>> hook.post_episodes(None, None); hook.calls, hook.seconds >= 0.0
    (1, True)
"""

from __future__ import annotations

import time

__all__ = ["TimedHook"]


class TimedHook:
    """Subclasses implement ``_post_episodes(trainer, batch)``; ``post_episodes`` times it."""

    seconds: float = 0.0

    def post_episodes(self, trainer, batch) -> None:
        start = time.perf_counter()
        try:
            self._post_episodes(trainer, batch)
        finally:
            self.seconds += time.perf_counter() - start

    def _post_episodes(self, trainer, batch) -> None:
        raise NotImplementedError
