"""``SkillChainingAgent``: the hierarchical agent that discovers its own options (sections 4, 5.1).

A :class:`~skillchain_torch.agents.HierarchicalAgent` (SMDP Sarsa over primitives and options,
intra-option Q-learning) whose bank starts empty and is filled by
:class:`~skillchain_torch.discovery.SkillChaining`: reaching the goal from a state no goal
option covers creates an option; after 10 episodes of gestation it joins the decisions with
``Q(s, o)`` set to the best value seen when its target fired; its initiation set is learned from
its executions; once that converges it becomes a target event, and options are created to
reach it, growing chains and trees backwards from the goal.

:meth:`SkillChainingAgent.build` takes every value from a named preset
(:mod:`skillchain_torch.presets`): ``"default"``, the agent ``skillchain train`` builds, or
``"paper"``, the values above; keyword arguments override either.

Compared with its parent class the agent:

* narrows every membership query by the no-overlap rule (:meth:`narrow`) for choosing only
  (options learn in their own sets),
* evaluates the base target events once per state and derives every option's target from them
  (:meth:`targets`),
* records the states of each execution and, when it ends, adds initiation-set examples,
  refits the classifier and drops the option's updates if it failed,
* creates options after each transition and applies the per-episode rules when episodes end.

Example:
    >>> import torch
    >>> agent = SkillChainingAgent.build(population=2, slots=4, order=1, seed=0)
    >>> agent.bank.live().any().item()                 # no options until the goal is reached
    False
    >>> obs = torch.tensor([[0.2, 0.9, 0.5, 0.5]] * 2, dtype=torch.float64)
    >>> agent.begin(obs).shape
    torch.Size([2])
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor

from skillchain_torch.discovery import (
    CONVERGENCE_EPISODES,
    CONVERGENCE_THRESHOLD,
    GESTATION_EPISODES,
    MAX_BRANCHING,
    InitiationReading,
    SkillChaining,
)
from skillchain_torch.discovery.readings import FIRST_READING
from skillchain_torch.features import FourierBasis
from skillchain_torch.options import GoalEvent, OptionBank, TerminationPredicate
from skillchain_torch.presets import (
    PRESET_FIELDS,
    Preset,
    env_values,
    instance_defaults,
    instance_slots,
    preset_named,
)

from .hierarchical import MAX_OPTION_STEPS, HierarchicalAgent, as_bool

__all__ = ["SkillChainingAgent"]


class SkillChainingAgent(HierarchicalAgent):
    """Population-batched skill chaining: P agents, K option slots each, discovered on-line.

    Args:
        bank: an :class:`OptionBank` (usually empty; :meth:`build` makes a preset's).
        events: the base target events, goal first (section 4.4).
        gestation, max_branching, convergence_threshold, convergence_episodes, overlap,
            wait_for_both_classes: the discovery rules (paper: 10, 3, 0.15, 2, on, off); see
            :class:`~skillchain_torch.discovery.SkillChaining`. The constructor's defaults are
            the paper's discovery rules; :meth:`build` takes every value from a preset.
        reading: the initiation-set reading (:class:`~skillchain_torch.discovery.
            InitiationReading`; default the first one, true everywhere until the first fit).
        policy_start: ``"zero"``, ``"top-level"`` or ``"top-level-shifted"``: how a joining
            option's policy starts
            (see :class:`~skillchain_torch.discovery.SkillChaining`).
        **kwargs: the :class:`HierarchicalAgent` arguments (``order``, ``alpha``, ``gamma``,
            ``epsilon``, ``seed``, ``option_epsilon``, ``max_option_steps``, ...).

    Attributes:
        discovery: the :class:`SkillChaining` state; its ``log`` holds the discovery events.
    """

    _PLAIN = HierarchicalAgent._PLAIN | {"q_decision", "_starts"}
    WANTS_VALUE = True  # gestation samples Q(s, d) of the decision in force

    def __init__(self, bank: OptionBank, events: Sequence[TerminationPredicate] = (GoalEvent(),),
                 gestation: int = GESTATION_EPISODES, max_branching: int = MAX_BRANCHING,
                 convergence_threshold: float = CONVERGENCE_THRESHOLD,
                 convergence_episodes: int = CONVERGENCE_EPISODES, overlap: bool = True,
                 wait_for_both_classes: bool = False,
                 reading: InitiationReading = FIRST_READING, policy_start: str = "zero",
                 value_start: str = "max-sample", value_bonus: float = 0.0,
                 **kwargs):  # fmt: skip
        super().__init__(bank, events=events, **kwargs)
        # Two starts read the linear head's weights and the Fourier basis directly.
        uses = [f"value_start={value_start!r}"] * (value_start == "agent") + \
            [f"policy_start={policy_start!r}"] * (policy_start != "zero")
        if uses and not (self.closed_form and type(self.features) is FourierBasis):
            raise ValueError(f"{' and '.join(uses)} fit the built-in LinearQHead over a "
                             f"FourierBasis, not {type(self.q_head).__name__} over "
                             f"{type(self.features).__name__}: use value_start='max-sample' "
                             "and policy_start='zero' (the paper's) with your own head")
        self.discovery = SkillChaining(
            self.bank, self.events, gestation=gestation, max_branching=max_branching,
            convergence_threshold=convergence_threshold,
            convergence_episodes=convergence_episodes,
            max_option_steps=kwargs.get("max_option_steps", MAX_OPTION_STEPS), overlap=overlap,
            wait_for_both_classes=wait_for_both_classes, reading=reading,
            policy_start=policy_start, value_start=value_start, value_bonus=value_bonus,
            top_basis=self.features, completion_reward=self.option_update.completion_reward,
        )  # fmt: skip
        # Q(s, d) of the decision d in force at the current state s, valued when s was reached
        # (before that step's update): the samples of gestation.
        self.q_decision = torch.zeros(self.population, dtype=torch.float64,
                                      device=self.obs.device)  # fmt: skip
        self._starts: Tensor | None = None  # agents whose option started this step, if any

    @classmethod
    def build(cls, population: int, preset: str | Preset = "default", seed: int | Tensor = 0,
              device: torch.device | str | None = None, map: str | None = None,
              **kwargs) -> SkillChainingAgent:  # fmt: skip
        """The agent of a named preset, with an empty bank of Fourier options per agent.

        Args:
            population: P, the number of independent agents.
            preset: ``"default"`` (the library's, which ``skillchain train`` builds) or
                ``"paper"`` (section 5.1's values); see :mod:`skillchain_torch.presets`.
            seed: agent p's random streams are keyed by ``seed + p``.
            map: the Pinball map whose paper ``order`` / ``alpha`` and library ``slots`` apply
                where the preset leaves them to the instance (``None``: the first instance's, 4,
                0.001 and 12 slots; the hard instance has 48).
            **kwargs: any :class:`~skillchain_torch.presets.Preset` field (``slots``,
                ``gestation``, ``option_alpha``, ``balanced``, ...) overrides the preset's
                value; ``top_head``, ``option_head``, ``initiation`` name the pieces
                (:mod:`~skillchain_torch.agents.pieces`: the paper's ``"fourier"``,
                ``"fourier"``, ``"logistic"`` by default, or ``"mlp"``); ``top_learner`` (a dict)
                goes to the top-level piece's builder (``"mlp"``: ``lr``, ``target_update``,
                ``bootstrap``); the rest go to the
                constructor (``events``, ``native``, ``reading``, ...) and win over the preset.

        Example:
            >>> paper = SkillChainingAgent.build(2, preset="paper", order=1, gestation=5)
            >>> paper.discovery.gestation, paper.discovery.policy_start
            (5, 'zero')
            >>> SkillChainingAgent.build(2, order=1).discovery.policy_start  # "default"
            'top-level'
        """
        bank, arguments = cls.build_arguments(population, preset, seed=seed, device=device,
                                              map=map, **kwargs)  # fmt: skip
        return cls(bank, **arguments)

    @staticmethod
    def build_arguments(population: int, preset: str | Preset = "default",
                        seed: int | Tensor = 0, device: torch.device | str | None = None,
                        map: str | None = None, **kwargs) -> tuple[OptionBank, dict]:  # fmt: skip
        """``(bank, constructor keyword arguments)`` of :meth:`build` (the trainer's
        ``SkillChainingRunAgent`` builds through this too, so both build the same agent)."""
        from .pieces import assemble_bank, top_level_arguments  # (they import the modules)

        fields = {k: kwargs.pop(k) for k in list(kwargs) if k in PRESET_FIELDS}
        names = {k: kwargs.pop(k, d) for k, d in (("top_head", "fourier"),
                                                  ("option_head", "fourier"),
                                                  ("initiation", "logistic"))}  # fmt: skip
        learner = kwargs.pop("top_learner", None)
        # The env's sizes (its specs; None: Pinball's 4 and 5).
        sizes = {k: v for k in ("obs_dim", "num_actions") if (v := kwargs.pop(k, None)) is not None}
        p = preset_named(preset).replace(**fields)
        order, alpha = instance_defaults(map)
        if p.slots is None:  # the library's for the map (off Pinball, map None: 12)
            p = p.replace(slots=instance_slots(map))
        if "obs_dim" in sizes:  # off Pinball: from the env's size, as TrainConfig.resolved
            order, alpha, scaled = env_values(p, sizes["obs_dim"], p.order)
            if "option_alpha" not in fields:
                p = p.replace(option_alpha=scaled)
        bank = OptionBank.build(population, p.slots, order=p.option_order, alpha=p.option_alpha,
                                seed=seed, device=device, degree=p.degree, lr=p.lr,
                                sweeps=p.sweeps, capacity=p.capacity, distance=p.distance,
                                balanced=p.balanced, keep_negatives=p.keep_negatives,
                                store_failures=p.store_failures,
                                constrain_nearest=p.constrain_nearest,
                                initial_bias=p.initiation_bias,
                                centered=p.initiation_centered, **sizes)  # fmt: skip
        bank = assemble_bank(bank, names["option_head"], names["initiation"], seed=seed)
        top = top_level_arguments(names["top_head"], population, bank.obs_dim,
                                  bank.num_actions + p.slots, p.gamma, seed, device,
                                  learner)  # fmt: skip
        reading = InitiationReading(p.gestation_positives, p.initiation_start,
                                    p.initiation_constrain, p.one_class_fits)  # fmt: skip
        arguments = dict(
            order=order if p.order is None else p.order,
            alpha=alpha if p.alpha is None else p.alpha, gamma=p.gamma, epsilon=p.epsilon,
            seed=seed, device=device, scale_step_size=p.scale_step_size,
            failure_bootstrap=p.failure_bootstrap, completion_reward=p.completion_reward,
            intra_option_primitives=p.intra_option_primitives,
            intra_option_target=p.intra_option_target,
            interruption=p.option_interruption, end_outside_set=p.end_outside_set,
            option_epsilon=p.option_epsilon,
            max_option_steps=p.max_option_steps, gestation=p.gestation,
            max_branching=p.max_branching, convergence_threshold=p.convergence_threshold,
            convergence_episodes=p.convergence_episodes, overlap=p.overlap, reading=reading,
            policy_start=p.policy_start, value_start=p.value_start, value_bonus=p.value_bonus,
        )  # fmt: skip
        return bank, {**arguments, **top, **kwargs}

    # ------------------------------------------------------------------ hooks
    def narrow(self, contains: Tensor) -> Tensor:
        return self.discovery.membership(contains)

    def targets(self, next_obs: Tensor, terminated: Tensor, contains: Tensor) -> Tensor:
        # Targets are the classifiers' own sets at s' (kept by membership), not the effective
        # ones in ``contains`` (see SkillChaining.membership).
        return self.discovery.targets(next_obs, terminated, self.discovery.last_raw)

    def _start_decisions(self, obs: Tensor, rows: Tensor) -> None:
        super()._start_decisions(obs, rows)
        self.discovery.start_episodes(self.obs, rows)
        chosen = self.last_q.gather(1, self.decision[:, None])[:, 0]
        self.q_decision = torch.where(rows, chosen, self.q_decision)
        self._begin_executions()

    def _options_starting(self, rows: Tensor) -> None:
        # Snapshots wait until the step's updates (and any dropped ones) are done.
        self._starts = rows if self._starts is None else self._starts | rows

    def _begin_executions(self) -> None:
        # (The compiled step reports its starts every step; most steps start none.)
        if self._starts is not None and bool(self._starts.any()):
            self.discovery.start_executions(self._starts, self.option)
        self._starts = None

    def transition(self, next_obs: Tensor, reward: Tensor, terminated: Tensor,
                   truncated: Tensor, stepped: Tensor) -> dict[str, Tensor]:  # fmt: skip
        contains, option, value = self.contains, self.option, self.q_decision
        every = self.all_stepped(stepped)  # masks by stepped are then skipped
        executing = option >= 0
        self.discovery.record_states(stepped, self.obs)
        self.discovery.record(executing if every else stepped & executing, self.duration,
                              self.obs)  # fmt: skip
        info = super().transition(next_obs, reward, terminated, truncated, stepped)
        terminated = as_bool(terminated)
        created = self.discovery.after_transition(
            contains=contains, option=option, value=value,
            reached=info["reached"], duration=info["duration"],
            decision_ended=info["decision_ended"],
            terminated=terminated if every else terminated & stepped, stepped=stepped,
        )  # fmt: skip
        if bool(created.any()):  # the new slot changes the memberships at s'
            self.contains = torch.where(created[:, None], self.membership(self.obs),
                                        self.contains)  # fmt: skip
            self.own_contains = torch.where(created[:, None], self._raw_contains,
                                            self.own_contains)  # fmt: skip
            self.discovery.created_rows_evaluated(created)
        # New decisions were valued before this step's update; an agent going on with its
        # option had no update this step, so its value now is the value then.
        if self.native:  # the compiled transition valued them (the same rule)
            value_next = self.last_value
        else:
            value_next = self.last_q.gather(1, self.decision[:, None])[:, 0]
            going_on = (stepped & ~info["decision_ended"]).nonzero()[:, 0]
            if going_on.numel() > 0:
                value_next[going_on] = self.q_head.q_value(self.last_phi, self.decision,
                                                           going_on)  # fmt: skip
        self.q_decision = value_next if every else torch.where(stepped, value_next,
                                                                 self.q_decision)  # fmt: skip
        self._begin_executions()
        return info

    def episodes_ended(self, rows: Tensor) -> None:
        self.discovery.end_episodes(rows, self.q_head)

    # ------------------------------------------------------------------ state
    def state_dict(self, *args, **kwargs):
        state = super().state_dict()
        state["discovery"] = self.discovery.state_dict()
        state["q_decision"] = self.q_decision.clone()
        return state

    def load_state_dict(self, state, strict: bool = True, assign: bool = False):
        super().load_state_dict(state)
        self.discovery.load_state_dict(state["discovery"])
        self.q_decision = state["q_decision"].to(self.obs.device).clone()

    def extra_repr(self) -> str:
        return super().extra_repr() + f", discovery={self.discovery!r}"
