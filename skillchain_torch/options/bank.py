"""The option bank: K option slots per agent with their status, metadata and three parts.

An option (paper section 2) is a policy, an initiation set and a termination condition. The bank
holds, batched over ``[P, K]``: the option Q-head (policies), the initiation classifier and, per
slot, the status (:class:`OptionStatus`), the target event, the parent slot and the creation
episode. Termination predicates are evaluated by :meth:`OptionBank.target_reached`.

Target of slot ``(p, k)``: if ``parent[p, k] >= 0`` it is the initiation set of agent p's slot
``parent[p, k]`` (a chain link); otherwise ``target_event[p, k] >= 0`` indexes the caller's list
of base target events (e.g. ``[GoalEvent(), RegionEvent(...)]``); ``-1`` in both: no target.

Example:
    >>> import torch
    >>> bank = OptionBank.build(population=2, slots=3, order=1, capacity=16)
    >>> bank.allocate(torch.tensor([True, True]), target_event=0, episode=5).tolist()
    [0, 0]
    >>> bank.allocate(torch.tensor([False, True]), parent=torch.tensor([-1, 0])).tolist()
    [-1, 1]
    >>> bank.status.tolist()                       # 1 = GESTATING
    [[1, 0, 0], [1, 1, 0]]
    >>> bank.available(torch.rand(2, 4, dtype=torch.float64)).any().item()  # not executable yet
    False
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import torch
from torch import Tensor, nn

from skillchain_torch.options.initiation import InitiationClassifier
from skillchain_torch.options.io import (
    CLASSIFIERS,
    Q_HEADS,
    Unregistered,
    _check_finite,
    _NonFinite,
    content_digest,
    lookup,
    read_torch_file,
)
from skillchain_torch.options.q_head import FourierOptionQHead, OptionQHead
from skillchain_torch.options.status import (
    OptionStatus,
    agent_index,
    check_slot_mask,
    slot_mask,
)
from skillchain_torch.options.termination import TerminationPredicate

FORMAT = "skillchain_torch.OptionBank"
FORMAT_VERSION = 1
_METADATA = ("status", "target_event", "parent", "created_episode")


class OptionBank(nn.Module):
    """Per-slot option state for a population of P agents with K slots each.

    Args:
        population: P; slots: K.
        q_head: an :class:`OptionQHead` with the same P and K (the option policies).
        classifier: an :class:`InitiationClassifier` with the same P and K.

    Buffers ``[P, K]`` (int64): ``status``, ``target_event`` (-1 none), ``parent`` (-1: the
    target is a base event such as the goal), ``created_episode`` (-1 for empty slots).
    ``state_dict()`` holds these plus the parts' state under ``q_head.`` / ``classifier.``.
    """

    def __init__(self, population: int, slots: int, q_head: OptionQHead,
                 classifier: InitiationClassifier):  # fmt: skip
        super().__init__()
        for part, name in ((q_head, "q_head"), (classifier, "classifier")):
            if (part.population, part.slots) != (population, slots):
                raise ValueError(f"{name} is for P={part.population}, K={part.slots}; the bank "
                                 f"has P={population}, K={slots}")  # fmt: skip
        self.population, self.slots = population, slots
        self.q_head = q_head
        self.classifier = classifier
        # The map the options were learned on (set by the trainer that learns them; saved with
        # the bank so a run on another map refuses them); None: not known.
        self.map: str | None = None
        self.legacy = False  # loaded from a file saved before banks recorded their environment
        device = classifier.trained.device  # (InitiationSet declares trained [P, K])
        self.register_buffer("status", torch.zeros(population, slots, dtype=torch.int64,
                                                   device=device))  # fmt: skip
        for name in _METADATA[1:]:
            self.register_buffer(name, torch.full_like(self.status, -1))

    @classmethod
    def build(cls, population: int, slots: int = 8, order: int = 3, alpha: float = 0.0005,
              seed: int | Tensor = 0, device: torch.device | str | None = None,
              obs_dim: int = 4, num_actions: int = 5,
              **classifier_kwargs: Any) -> OptionBank:  # fmt: skip
        """The paper's bank: Fourier option heads and default classifiers, for an
        environment with ``obs_dim`` observation dims (in ``[0, 1]``) and ``num_actions``
        primitive actions (Pinball's 4 and 5 by default)."""
        q_head = FourierOptionQHead(population, slots, order=order, alpha=alpha, device=device,
                                    obs_dim=obs_dim, num_actions=num_actions)  # fmt: skip
        classifier = InitiationClassifier(population, slots, seed=seed, device=device,
                                          obs_dim=obs_dim, **classifier_kwargs)  # fmt: skip
        return cls(population, slots, q_head, classifier)

    # ------------------------------------------------------------------------------- queries
    def live(self) -> Tensor:
        """``[P, K]``: slots holding an option (status != EMPTY)."""
        return self.status != OptionStatus.EMPTY

    def executable(self) -> Tensor:
        """``[P, K]``: options in the repertoire (LEARNING or LEARNED; gestating ones are not)."""
        return self.status >= OptionStatus.LEARNING

    def available(self, obs: Tensor, contains: Tensor | None = None) -> Tensor:
        """``[P, K]``: executable options whose initiation set contains ``obs [P, 4]``.

        ``contains`` may pass ``classifier.contains(obs)`` when the caller already has it.
        """
        member = self.classifier.contains(obs) if contains is None else contains
        return self.executable() & member

    @property
    def obs_dim(self) -> int:
        """The observation size the option heads (and initiation sets) take (the option head
        declares it: :class:`~skillchain_torch.interfaces.OptionHead`)."""
        return int(self.q_head.obs_dim)

    @property
    def num_actions(self) -> int:
        """The primitive actions of the option Q-heads."""
        return int(self.q_head.num_actions)

    def environment(self) -> dict[str, Any]:
        """What the options were learned on, as saved: ``map``, ``obs_dim``, ``num_actions``."""
        return {"map": self.map, "obs_dim": self.obs_dim, "num_actions": self.num_actions}

    def learned_on(self, map: str) -> None:
        """Record the env the options are being learned on (``map``: a Pinball map or a
        ``gymnasium:ID``), saved with them so that a run on another env refuses them; a bank
        whose env is already known keeps it.

            >>> bank = OptionBank.build(population=1, slots=1, order=1)
            >>> bank.learned_on("pinball_simple_single"); bank.environment()["map"]
            'pinball_simple_single'
        """
        if map is not None and self.map is None and not self.legacy:
            self.map = str(map)

    def feature_settings(self) -> dict[str, Any]:
        """The options' feature settings, as saved: the Q-head class and its basis (Fourier
        ``order``, or the MLP's ``hidden``/``layers``), and the initiation classifiers'
        polynomial ``degree`` and ``centered`` inputs."""
        head = self.q_head.config
        out: dict[str, Any] = {"q_head": type(self.q_head).__name__}
        out.update({k: head[k] for k in ("order", "hidden", "layers") if k in head})
        cls = self.classifier.config
        out.update(initiation_degree=cls.get("degree"), initiation_centered=cls.get("centered"))
        return out

    def check_environment(self, source: str | os.PathLike, map: str | None = None,
                          obs_dim: int | None = None,
                          num_actions: int | None = None) -> None:  # fmt: skip
        """``ValueError`` naming the field if the bank was learned on another map, or its
        parts take another observation size or action count, than a run's (``None``: not
        checked). A bank saved without its map (:attr:`legacy`) passes the map check."""
        ours = self.environment()
        for field, want, flag in (("map", map, "--map"), ("obs_dim", obs_dim, None),
                                  ("num_actions", num_actions, None)):  # fmt: skip
            have = ours[field]
            if want is None or have is None or have == want:
                continue
            where = f" ({flag} {want})" if flag else ""
            raise ValueError(f"{source}: the options were learned with {field} = {have!r}, but "
                             f"this run has {field} = {want!r}{where}")  # fmt: skip

    def full(self) -> Tensor:
        """``[P]``: agents with no empty slot left."""
        return self.live().all(-1)

    def first_empty(self, agents: Tensor | None = None) -> Tensor:
        """``LongTensor [P]``: each chosen agent's first empty slot, -1 if full or not chosen."""
        empty = ~self.live()
        if agents is not None:
            if agents.dtype != torch.bool or tuple(agents.shape) != (self.population,):
                raise ValueError(f"agents must be a BoolTensor [P={self.population}]")
            empty = empty & agents.to(empty.device)[:, None]
        first = empty.to(torch.int64).argmax(-1)
        return torch.where(empty.any(-1), first, torch.full_like(first, -1))

    def target_reached(self, obs: Tensor, terminated: Tensor | None = None,
                       events: Sequence[TerminationPredicate] = (),
                       contains: Tensor | None = None) -> Tensor:  # fmt: skip
        """``BoolTensor [P, K]``: each live slot's termination predicate at ``obs`` (= s').

        Args:
            obs: ``[P, 4]``; terminated: the env's flag ``[P]`` (needed by :class:`GoalEvent`).
            events: the base target events indexed by ``target_event``.
            contains: ``classifier.contains(obs)``, if already computed.
        """
        reached = torch.zeros_like(self.live())
        chained = self.parent >= 0
        if bool(chained.any()):
            member = self.classifier.contains(obs) if contains is None else contains
            reached = reached | (chained & member.gather(1, self.parent.clamp(min=0)))
        base = ~chained & (self.target_event >= 0)
        for i in torch.unique(self.target_event[base]).tolist():
            if i >= len(events):
                raise ValueError(f"target event {i} used by a slot, but only {len(events)} given")
            fired = events[i](obs, terminated).to(reached.device)
            reached = reached | (base & (self.target_event == i) & fired[:, None])
        return reached & self.live()

    # ------------------------------------------------------------------------------- changes
    @torch.no_grad()
    def allocate(self, agents: Tensor, target_event: int | Tensor = -1,
                 parent: int | Tensor = -1, episode: int | Tensor = -1) -> Tensor:  # fmt: skip
        """Create a GESTATING option in the first empty slot of each agent in ``agents [P]``.

        The slot's Q-head weights and classifier are reset; metadata is set from the (int or
        ``[P]``) arguments. Returns the slot per agent, -1 where not chosen or full.
        """
        slot = self.first_empty(agents)
        mask = slot_mask(slot >= 0, slot, self.slots)
        self.q_head.reset_slots(mask)
        self.classifier.reset_slots(mask)
        values = {"status": int(OptionStatus.GESTATING), "target_event": target_event,
                  "parent": parent, "created_episode": episode}  # fmt: skip
        for name, value in values.items():
            value = torch.as_tensor(value, dtype=torch.int64, device=self.status.device)
            buffer = getattr(self, name)
            buffer.copy_(torch.where(mask, value.expand(self.population)[:, None], buffer))
        return slot

    @torch.no_grad()
    def set_status(self, mask: Tensor, status: OptionStatus | int) -> None:
        """Set the status of the slots in ``mask [P, K]`` (e.g. GESTATING -> LEARNING)."""
        mask = check_slot_mask(mask, self.population, self.slots).to(self.status.device)
        self.status[mask] = int(OptionStatus(status))

    @torch.no_grad()
    def free(self, mask: Tensor) -> None:
        """Empty the slots in ``mask [P, K]`` and reset their parts."""
        mask = check_slot_mask(mask, self.population, self.slots).to(self.status.device)
        self.q_head.reset_slots(mask)
        self.classifier.reset_slots(mask)
        self.status[mask] = int(OptionStatus.EMPTY)
        for name in _METADATA[1:]:
            getattr(self, name)[mask] = -1

    def select_agents(self, index, seeds: Tensor | None = None) -> OptionBank:
        """A new bank of agents ``index`` (repeats replicate: ``[p] * P2`` gives P2 copies of
        agent p's options). ``seeds [P2]`` reseeds the parts' random streams."""
        index = agent_index(index, self.population)
        new = type(self)(len(index), self.slots, self.q_head.select_agents(index, seeds),
                         self.classifier.select_agents(index, seeds))  # fmt: skip
        for name in _METADATA:
            getattr(new, name).copy_(getattr(self, name)[index.to(self.status.device)])
        new.map, new.legacy = self.map, self.legacy
        return new

    @classmethod
    def concat(cls, banks: list[OptionBank]) -> OptionBank:
        """One bank of the agents of ``banks``, in order (the inverse of splitting a population
        with :meth:`select_agents`): per-agent state is joined, shared state (feature bases)
        comes from the first bank.

        Example:
            >>> bank = OptionBank.build(population=3, slots=2)
            >>> OptionBank.concat([bank.select_agents([0]), bank.select_agents([1, 2])]).population
            3
        """
        first = banks[0]
        population = sum(b.population for b in banks)
        # Per-agent entries are those whose leading size follows the population (a 1- and a
        # 2-agent bank differ there); comparing shapes avoids guessing from a coincident size.
        one, two = first.select_agents([0]).state_dict(), first.select_agents([0, 0]).state_dict()
        per_agent = {k for k in one if one[k].shape != two[k].shape}
        new = first.select_agents([0] * population)
        states = [b.state_dict() for b in banks]
        joined = {k: torch.cat([s[k] for s in states]) if k in per_agent else v
                  for k, v in states[0].items()}
        new.load_state_dict(joined)
        return new

    # ------------------------------------------------------------------------------- files
    def save(self, path: str | os.PathLike) -> None:
        """Write the bank (format version, parts' configs, what the options were learned on
        (:meth:`environment`), their :meth:`feature_settings`, all state, and a ``sha256``
        digest of the rest that :meth:`load` verifies) with ``torch.save``."""
        payload = self._payload()
        payload["sha256"] = content_digest(payload)
        torch.save(payload, path)

    def _payload(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "version": FORMAT_VERSION,
            "population": self.population,
            "slots": self.slots,
            "q_head": {"class": type(self.q_head).__name__, "config": dict(self.q_head.config)},
            "classifier": {"class": type(self.classifier).__name__,
                           "config": dict(self.classifier.config)},
            "environment": self.environment(),
            "features": self.feature_settings(),
            "state": {k: v.detach().cpu() for k, v in self.state_dict().items()},
        }

    @classmethod
    def load(cls, path: str | os.PathLike, q_head: OptionQHead | None = None,
             classifier: InitiationClassifier | None = None,
             device: torch.device | str | None = None) -> OptionBank:  # fmt: skip
        """Read a file written by :meth:`save`; the parts are rebuilt from the stored configs
        unless given (then they must match the stored shapes). Raises ``ValueError`` (one line,
        naming the file) for an unreadable, foreign, other-version or mismatched file, one
        whose digest, recorded environment or feature settings disagree with its contents,
        and one with NaN or infinite values (a diverged learner). Files saved before banks
        recorded their environment load with :attr:`map` ``None`` and :attr:`legacy` set."""
        payload = read_torch_file(path, "OptionBank file")
        if not isinstance(payload, dict) or payload.get("format") != FORMAT:
            kind = ""
            if isinstance(payload, dict) and {"format_version", "agent", "trainer"} <= set(payload):
                kind = "; it is a training checkpoint (a skill-chaining run writes its options "
                kind += "to DIR/options.pt)"
            raise ValueError(f"{path}: not an OptionBank file (format {FORMAT!r} expected{kind})")
        if payload.get("version") != FORMAT_VERSION:
            raise ValueError(f"{path}: OptionBank format version {payload.get('version')!r}, "
                             f"this library reads version {FORMAT_VERSION}")  # fmt: skip
        if "sha256" in payload:  # files saved before banks had one load unverified
            try:
                actual = content_digest({k: v for k, v in payload.items() if k != "sha256"})
            except Exception as error:  # a value the digest cannot take: not what was saved
                raise ValueError(f"{path}: OptionBank contents cannot be digested "
                                 f"({error})") from None  # fmt: skip
            if payload["sha256"] != actual:
                raise ValueError(f"{path}: checksum mismatch (sha256 stored "
                                 f"{str(payload['sha256'])[:16]}..., contents {actual[:16]}...): "
                                 f"the file was altered or damaged after it was written")
        try:
            population, slots = int(payload["population"]), int(payload["slots"])
            if q_head is None:
                head_class = lookup(Q_HEADS, payload["q_head"]["class"], "option head",
                                    "register_q_head")  # fmt: skip
                q_head = head_class(**payload["q_head"]["config"], device=device)
            if classifier is None:  # files saved before classifiers had a class name: the built-in
                name = payload["classifier"].get("class", "InitiationClassifier")
                kind = lookup(CLASSIFIERS, name, "initiation classifier", "register_classifier")
                classifier = kind(**payload["classifier"]["config"], device=device)
            bank = cls(population, slots, q_head, classifier)
            state = payload["state"]
            _check_finite(state, population)
            bank.load_state_dict(state)
        except Unregistered as error:
            raise ValueError(f"{path}: {error}") from None
        except _NonFinite as error:
            raise ValueError(f"{path}: {error}; a diverged bank is not loaded") from None
        except (KeyError, TypeError, RuntimeError, ValueError, AttributeError, IndexError,
                OverflowError) as error:  # fmt: skip
            reason = " ".join(str(error).split())[:300]
            raise ValueError(f"{path}: OptionBank file does not match ({reason})") from None
        bank._read_recorded(path, payload)
        return bank

    def _read_recorded(self, path, payload: dict) -> None:
        """Check the file's ``environment`` and ``features`` against the rebuilt parts."""
        env, features = payload.get("environment"), payload.get("features")
        if env is None and features is None:  # saved before banks recorded them
            self.legacy = True
            return
        for name, recorded, actual in (("environment", env, self.environment()),
                                       ("features", features, self.feature_settings())):
            if not isinstance(recorded, dict):
                raise ValueError(f"{path}: field {name!r} is not a dict")
            for key, value in actual.items():
                if key == "map":
                    continue
                if recorded.get(key) != value:
                    raise ValueError(f"{path}: field '{name}.{key}' is {recorded.get(key)!r}, "
                                     f"but the bank's parts have {value!r}")  # fmt: skip
        saved_map = env.get("map")
        if saved_map is not None and not isinstance(saved_map, str):
            raise ValueError(f"{path}: field 'environment.map' is {saved_map!r}, not a name")
        self.map = saved_map

    @classmethod
    def from_agent(cls, path: str | os.PathLike, agent: int, population: int,
                   seeds: Tensor | None = None, device: torch.device | str | None = None
                   ) -> OptionBank:  # fmt: skip
        """Agent ``agent``'s options from a saved population, replicated ``population`` times
        (e.g. to start a "given options" run)."""
        return cls.load(path, device=device).select_agents([agent] * population, seeds)

    def extra_repr(self) -> str:
        return f"population={self.population}, slots={self.slots}"


def target_indicator(bank: OptionBank, base_fired: Tensor, contains: Tensor) -> Tensor:
    """``[P, K]``: each live slot's target event at a state, from the base events' values
    ``base_fired [P, E]`` and the initiation-set memberships ``contains [P, K]`` there.

    The same answer as :meth:`OptionBank.target_reached`, without evaluating any event again.
    """
    chained = bank.parent >= 0
    from_parent = contains.gather(1, bank.parent.clamp(min=0))
    if base_fired.shape[1] == 0:
        from_base = torch.zeros_like(from_parent)
    else:
        index = bank.target_event.clamp(min=0, max=base_fired.shape[1] - 1)
        from_base = base_fired.gather(1, index) & (bank.target_event >= 0)
    return torch.where(chained, from_parent, from_base) & bank.live()
