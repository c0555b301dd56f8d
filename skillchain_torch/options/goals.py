"""Goals that mean success: which transitions fire the task's goal event (issue 53).

Skill chaining builds its first options toward the goal event (paper section 4). In Pinball the
only termination is the hole, so the env's ``terminated`` flag is the goal. Elsewhere it may
not be: LunarLander terminates on a crash too, and CartPole terminates only when the pole
falls. :func:`goal_event` builds the goal from a name:

* ``"terminated"``: the env's own termination (:class:`~.termination.GoalEvent`);
* ``"terminated-positive"``: terminated with a positive last reward (LunarLander: landed,
  +100, not crashed, -100);
* ``"MODULE:FUNCTION"``: the user's function of the transition's TensorDict (``observation``
  ``[P, D]`` in the unit box, ``terminated`` and ``reward`` ``[P]``) returning ``BoolTensor
  [P]``; it fires only where the episode terminated.

:func:`env_goal` says which goal an env of the library's studies takes by default, and which
envs refuse one: a goal that would mean failure is refused rather than silently chained.

Example:
    >>> import torch
    >>> goal = goal_event("terminated-positive")
    >>> obs = torch.zeros(3, 8, dtype=torch.float64)
    >>> goal(obs, torch.tensor([True, True, False]), torch.tensor([100.0, -100.0, 5.0])).tolist()
    [True, False, False]
    >>> env_goal("gymnasium:LunarLander-v3")
    'terminated-positive'
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

import torch
from tensordict import TensorDict
from torch import Tensor

from skillchain_torch.options.termination import GoalEvent

__all__ = ["GOALS", "ENV_GOALS", "TransitionGoal", "goal_event", "env_goal", "goal_note"]

GOALS = ("terminated", "terminated-positive")  # the built-in names; else MODULE:FUNCTION

# The goal each env of the library's studies takes (None: none means success; give --goal).
ENV_GOALS: dict[str, str | None] = {
    "MountainCar-v0": "terminated",  # terminates only at the flag
    "Acrobot-v1": "terminated",  # terminates only when the tip crosses the line
    "LunarLander-v3": "terminated-positive",  # terminates on landing (+100) and crashes (-100)
    "CartPole-v1": None,  # terminates only when the pole falls or the cart leaves: failure
    "CartPole-v0": None,
}


class TransitionGoal:
    """A goal event from a function of the transition: fires where the episode terminated
    and ``function(td)`` holds, ``td`` holding ``observation``, ``terminated`` and ``reward``.

    Its ``wants_reward`` tells the agents to pass the transition's reward (the other events
    read the observation and ``terminated`` alone).

    Example:
        >>> goal = TransitionGoal(lambda td: td["reward"] > 0, name="positive")
        >>> obs = torch.zeros(2, 4, dtype=torch.float64)
        >>> goal(obs, torch.tensor([True, True]), torch.tensor([1.0, -1.0])).tolist()
        [True, False]
    """

    wants_reward = True

    def __init__(self, function: Callable[[TensorDict], Tensor], name: str = "goal"):
        self.function, self.name = function, name

    def __call__(self, obs: Tensor, terminated: Tensor | None = None,
                 reward: Tensor | None = None) -> Tensor:  # fmt: skip
        if terminated is None:
            raise ValueError(f"goal {self.name!r} needs the environment's terminated flag")
        terminated = terminated.reshape(obs.shape[0]).to(torch.bool)
        if reward is None:  # (an episode's first state: nothing terminated there)
            reward = torch.zeros(obs.shape[0], dtype=torch.float64, device=obs.device)
        td = TensorDict(observation=obs, terminated=terminated, reward=reward,
                        batch_size=[obs.shape[0]])  # fmt: skip
        fired = torch.as_tensor(self.function(td), device=obs.device)
        if fired.shape != terminated.shape or fired.dtype != torch.bool:
            raise ValueError(f"goal {self.name!r} must return a BoolTensor [{obs.shape[0]}], got "
                             f"{fired.dtype} {tuple(fired.shape)}")  # fmt: skip
        return terminated & fired

    def __repr__(self) -> str:
        return f"TransitionGoal(name={self.name!r})"


def _terminated_positive(td: TensorDict) -> Tensor:
    return td["reward"] > 0


def goal_event(spec: str | None) -> GoalEvent | TransitionGoal:
    """The goal event named ``spec`` (``None``: ``"terminated"``); ``ValueError`` in one line
    for an unknown name or a ``MODULE:FUNCTION`` that does not import."""
    if spec is None or spec == "terminated":
        return GoalEvent()
    if spec == "terminated-positive":
        return TransitionGoal(_terminated_positive, name="goal")
    module_name, _, function_name = spec.rpartition(":")
    if not module_name or not function_name:
        raise ValueError(f"goal {spec!r}: expected one of {', '.join(GOALS)} or MODULE:FUNCTION")
    try:
        function = getattr(importlib.import_module(module_name), function_name)
    except (ImportError, AttributeError) as err:
        raise ValueError(f"goal {spec!r}: cannot import {function_name} from {module_name} "
                         f"({err})") from None  # fmt: skip
    if not callable(function):
        raise ValueError(f"goal {spec!r}: {function_name} is not callable")
    return TransitionGoal(function, name="goal")


def env_goal(env: str | None) -> str | None:
    """The goal an env takes when none is given: ``"terminated"`` for Pinball (``env``
    ``None``) and for envs the library does not know, the entry of :data:`ENV_GOALS` for
    those it does (``None``: it has no goal that means success)."""
    if env is None:
        return "terminated"
    env_id = env.rpartition(":")[2]
    return ENV_GOALS.get(env_id, "terminated")


def goal_note(env: str | None) -> str | None:
    """One line for an env the library does not know (its goal is taken to be ``terminated``),
    else ``None``."""
    if env is None or env.rpartition(":")[2] in ENV_GOALS:
        return None
    return (f"{env}: the goal event is the env's own 'terminated' flag; if a termination can "
            "mean failure, pass --goal terminated-positive or --goal MODULE:FUNCTION")
