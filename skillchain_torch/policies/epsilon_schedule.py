"""A linear annealing of the top level's exploration, by the step count, as TorchRL's
``EGreedyModule`` anneals (``eps_init`` to ``eps_end`` over ``annealing_num_steps``).

The paper's linear agents explore at a constant ``epsilon = 0.01``: a zero-initialised linear
head is optimistic where every return is negative, and each visit lowers only what it touches.
A network's generalisation lowers every value together, so the neural agents need the undirected
exploration DQN starts with (``results/neural/README.md``: at a constant 0.01 neither neural
agent learns on Acrobot-v1 in 50 episodes).

Why not ``torchrl.modules.EGreedyModule`` itself: the agents decide with
:func:`~skillchain_torch.policies.epsilon_greedy`, whose two uniforms per decision keep the
population's random streams in step (the reproducibility contract); only the annealing rule is
borrowed, under TorchRL's names.

Example:
    >>> schedule = LinearEpsilon(eps_init=1.0, eps_end=0.05, annealing_num_steps=100)
    >>> [schedule(step) for step in (0, 50, 100, 1000)]
    [1.0, 0.525, 0.05, 0.05]
"""

from __future__ import annotations

__all__ = ["LinearEpsilon", "checked_epsilon"]


def checked_epsilon(value: float, name: str = "epsilon") -> float:
    """``value`` as a float, or ``ValueError`` naming ``name`` unless it is in [0, 1].

    >>> checked_epsilon(0.5), checked_epsilon(1)
    (0.5, 1.0)
    """
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"{name} must be in [0, 1], got {value}")
    return float(value)


class LinearEpsilon:
    """``epsilon(step)``: ``eps_init`` at step 0, linearly down to ``eps_end`` at
    ``annealing_num_steps``, ``eps_end`` after.

    Args:
        eps_init, eps_end: in [0, 1].
        annealing_num_steps: >= 1, in the steps the caller counts (the trainer counts agent
            steps: every active agent steps once per population step).
    """

    def __init__(self, eps_init: float, eps_end: float, annealing_num_steps: int):
        self.eps_init = checked_epsilon(eps_init, "eps_init")
        self.eps_end = checked_epsilon(eps_end, "eps_end")
        if annealing_num_steps < 1:
            raise ValueError(f"annealing_num_steps must be >= 1, got {annealing_num_steps}")
        self.annealing_num_steps = int(annealing_num_steps)

    def __call__(self, step: int) -> float:
        if step >= self.annealing_num_steps:
            return self.eps_end
        fraction = step / self.annealing_num_steps
        return self.eps_init + (self.eps_end - self.eps_init) * fraction

    def __repr__(self) -> str:
        return (f"LinearEpsilon(eps_init={self.eps_init}, eps_end={self.eps_end}, "
                f"annealing_num_steps={self.annealing_num_steps})")
