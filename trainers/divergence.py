"""Divergence: a learner of some agent holds a NaN or infinite weight, and the run stops with
a message naming the learner, the agents, what to lower, and what was saved.

A mixin of :class:`~.population.PopulationTrainer` (it reads ``agent``, ``config``,
``episodes_done``, ``out_dir``). The learners are found through the pieces' interfaces: the
top-level head's ``weight`` or its per-agent parameters, the option heads' ``slot_tensors``,
the initiation sets' ``weight``/``bias`` or their per-agent parameters.

Example:
    >>> import torch
    >>> from skillchain_torch.trainers import PopulationTrainer, TrainConfig
    >>> trainer = PopulationTrainer(TrainConfig(agent="skill-chaining", runs=2, episodes=1))
    >>> trainer.agent.q_head.weight[1, 0, 0] = float("nan")
    >>> try:
    ...     trainer.check_learners()
    ... except FloatingPointError as err:  # a Diverged
    ...     print(err.agents)
    [1]
"""

from __future__ import annotations

import json
import math

import numpy as np
import torch

from .user_agent import run_record

__all__ = ["Diverged", "DivergenceCheck"]


class Diverged(FloatingPointError):
    """A learner's weights became NaN or infinite, so the run stopped.

    ``agents``: the diverged agents' ids; ``learners``: ``{learner: [agent ids]}``. The
    message (one line) names them and the run parameter to change.
    """

    def __init__(self, message: str, agents: list[int], learners: dict[str, list[int]]):
        super().__init__(message)
        self.agents, self.learners = agents, learners


def _per_agent(module, population: int, names: tuple[str, ...] = ("weight",)) -> list:
    """A learner's tensors to check for divergence, each ``[P, ...]``: the built-in
    ``names`` where the module has them, and the trainable parameters of a user's model that
    hold one slice per agent (a parameter shared by all agents cannot be told apart by agent
    and is not checked)."""
    tensors = [getattr(module, n) for n in names if isinstance(getattr(module, n, None),
                                                               torch.Tensor)]  # fmt: skip
    seen = {id(t) for t in tensors}
    tensors += [p for p in module.parameters() if p.requires_grad and id(p) not in seen
                and p.dim() >= 1 and p.shape[0] == population]  # fmt: skip
    return [t.detach() for t in tensors]


class DivergenceCheck:
    """:meth:`check_learners` for the trainer."""

    # ------------------------------------------------------------------ divergence
    def _learners(self, rows: torch.Tensor | None) -> list[tuple[str, str, list[torch.Tensor]]]:
        """``(learner, advice, tensors)`` with agents on dim 0: the learners of the agents at
        active rows ``rows`` (``None``: all P agents, after a flush)."""
        agent, cfg = self.agent, self.config
        if rows is None:
            agent.flush()
            ids = None
        elif rows.numel() == 1:  # the usual case: views, no copies
            ids = int(agent.index[rows])
        else:
            ids = agent.index[rows]

        def pick(t: torch.Tensor) -> torch.Tensor:
            if ids is None:
                return t
            if isinstance(ids, int):
                return t[ids:ids + 1]
            return t.index_select(0, ids.to(t.device))

        working = getattr(agent, "working_weights", None)  # the flat agent's, without a flush
        if rows is not None and working is not None:
            top = working(rows)
        else:
            top = [pick(t) for t in _per_agent(agent.q_head, agent.population)]
        learners = [("the top-level Q-head", f"lower --alpha (now {cfg.alpha:g})",
                     top if isinstance(top, list) else [top])]
        bank = getattr(agent, "bank", None)
        if bank is None:
            return self._for_user(learners)
        heads = [pick(t) for t in bank.q_head.slot_tensors().values()]  # [P, K, ...]
        alpha = bank.q_head.config.get("alpha")
        if cfg.agent == "given-options":
            advice = (f"their step size (alpha {alpha:g}) is the one saved in --options "
                      f"{cfg.options}" if alpha is not None else "")
        elif cfg.option_alpha == 0:  # they never learn: a joining option copies the top level
            advice = f"they only copy the top-level Q-head: lower --alpha (now {cfg.alpha:g})"
        else:
            advice = f"lower --option-alpha (now {cfg.option_alpha:g})"
        classifier = bank.classifier
        learners += [
            ("the option Q-heads", advice, heads),
            ("the initiation classifiers",
             f"their step size (lr {classifier.lr:g}) is not a run parameter",
             [pick(t) for t in _per_agent(classifier, agent.population, ("weight", "bias"))]),
        ]
        return self._for_user(learners)

    def _for_user(self, learners: list) -> list:
        """The advice for an agent built in Python, whose step sizes no flag set."""
        if not getattr(self, "user_agent", False):
            return learners
        return [(name, "lower its step size where you built the agent", tensors)
                for name, _, tensors in learners]  # fmt: skip

    def check_learners(self, rows: torch.Tensor | None = None) -> None:
        """Raise :class:`Diverged` if a learner of the agents at active rows ``rows`` (default:
        every agent) holds a NaN or infinite weight. One reduction per tensor and one sync
        when all is well."""
        learners = self._learners(rows)
        # A sum is non-finite if any term is (an overflowing sum of finite weights is looked
        # at below and passes).
        sums = [t.sum() for _, _, tensors in learners for t in tensors]
        if math.isfinite(torch.stack(sums).sum()):
            return
        ids = (torch.arange(self.config.runs) if rows is None else self.agent.index[rows]).tolist()
        found: dict[str, list[int]] = {}
        parts = []
        for learner, advice, tensors in learners:
            bad = torch.zeros(len(ids), dtype=torch.bool)
            for t in tensors:
                bad |= ~torch.isfinite(t.reshape(len(ids), -1)).all(-1).cpu()
            if bool(bad.any()):
                found[learner] = [ids[i] for i in bad.nonzero().flatten().tolist()]
                parts.append(f"{learner} of agents {_short(found[learner])}"
                             + (f": {advice}" if advice else ""))
        if not found:
            return
        agents = sorted({a for group in found.values() for a in group})
        done = sorted({int(self.episodes_done[a]) for a in agents})
        done_text = str(done[0]) if len(done) == 1 else f"{done[0]}-{done[-1]}"
        last = None
        if self.out_dir is not None:
            from .checkpoint import latest_checkpoint

            last = latest_checkpoint(self.out_dir)
        saved = (f"returns so far in {self.out_dir / 'partial_returns.npy'}; last good "
                 f"checkpoint {last if last is not None else 'none (none was written yet)'}"
                 if self.out_dir is not None else "no out_dir, nothing saved")
        raise Diverged(
            f"agents {_short(agents)} have non-finite weights (NaN or infinite) after "
            f"{done_text} completed episodes: " + "; ".join(parts)
            + f". The run diverged and stopped: {saved}", agents, found)

    def _diverge(self, error: FloatingPointError) -> FloatingPointError:
        """The :class:`Diverged` for ``error`` (the flat agent's own check names no learner:
        every learner is checked), after saving the returns so far; ``error`` itself if no
        learner is non-finite."""
        if not isinstance(error, Diverged):
            try:
                self.check_learners()
                return error
            except Diverged as found:
                error = found
        self.diverged = error
        if self.out_dir is not None:
            out = self.out_dir
            out.mkdir(parents=True, exist_ok=True)
            np.save(out / "partial_returns.npy", self.returns)
            np.save(out / "partial_lengths.npy", self.lengths)
            info = {"error": str(error), "agents": error.agents, "learners": error.learners,
                    "episodes_done": self.episodes_done.tolist(),
                    "config": run_record(self)}
            (out / "diverged.json").write_text(json.dumps(info, indent=1) + "\n")
        return error


def _short(values: list[int], most: int = 10) -> str:
    """``[0, 1, 2]``, or the first ``most`` and how many in all."""
    if len(values) <= most:
        return str(values)
    return f"[{', '.join(map(str, values[:most]))}, ... ({len(values)} in all)]"
