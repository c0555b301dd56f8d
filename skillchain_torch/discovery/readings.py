"""Readings of the paper's underspecified initiation-set rules, as one named parameter set.

Section 5.1 says the classifier was "initialized to be true everywhere", that "states on
trajectories that reached its goal within 250 steps were used as positive examples, and the
start states of trajectories that did not were used as negative examples", and that "after this
learning period we additionally constrained the initiation set to contain only points within a
Euclidean distance of 0.1 of a positive example". It leaves open what the set is between the
end of gestation and the first successful executions. Each open point is a field here:

=========================  =========================================================  =========
field                      values                                                     first
                                                                                      reading
=========================  =========================================================  =========
``gestation_positives``    N: each time an option's target fires *during gestation*   0
                           (its creation included), the last N states of that
                           trajectory become positive examples (0: none; 20: the
                           deep-skill-chaining code's; 250: "within 250 steps")
``start``                  how the set starts when gestation ends: ``"everything"``   everything
                           (untrained, true everywhere), ``"biased"`` (true through
                           a positive intercept, ``initial_bias``), ``"fitted"``
                           (fitted on the gestation positives)
``constrain``              when the 0.1 distance constraint applies: ``"learned"``    learned
                           (once the set has converged) or ``"start"`` (from the
                           end of gestation)
``one_class_fits``         a fit may see one class only (``False``: wait for both,    True
                           ``wait_for_both_classes``)
=========================  =========================================================  =========

The first reading (column "first reading") is what this library ran before the readings were
parameters, and stays :class:`~skillchain_torch.discovery.SkillChaining`'s default. The
trainer's default (:data:`DEFAULT_READING`) is ``pos20-fitted-cstart``: in the screen of
``results/screening/README.md`` (20 runs), with options whose policy and ``Q(s, o)`` start from
the agent's own values, it kept every agent's options alive and beat flat agents on episodes
51-100, while under the first reading most options died (fitted on one failure, empty).

Example:
    >>> r = InitiationReading(gestation_positives=250, start="fitted", constrain="start")
    >>> r.name
    'pos250-fitted-cstart'
    >>> InitiationReading.parse("pos20-everything-clearned-wait") == InitiationReading(
    ...     gestation_positives=20, start="everything", constrain="learned", one_class_fits=False)
    True
    >>> InitiationReading(start="sometimes")
    Traceback (most recent call last):
    ...
    ValueError: reading start must be one of everything, biased, fitted, got 'sometimes'
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

__all__ = ["InitiationReading", "STARTS", "CONSTRAINTS", "FIRST_READING", "DEFAULT_READING"]

STARTS = ("everything", "biased", "fitted")
CONSTRAINTS = ("learned", "start")


@dataclass(frozen=True)
class InitiationReading:
    """One reading of the initiation-set rules (see the module docstring).

    Args:
        gestation_positives: states before each target hit during gestation kept as positive
            examples (0: none).
        start: ``"everything"``, ``"biased"`` or ``"fitted"``.
        constrain: ``"learned"`` or ``"start"``.
        one_class_fits: refit after every new example even if the slot holds one class only.
    """

    gestation_positives: int = 0
    start: str = "everything"
    constrain: str = "learned"
    one_class_fits: bool = True

    def __post_init__(self):
        n = self.gestation_positives
        if isinstance(n, bool) or not isinstance(n, int) or not 0 <= n <= 100_000:
            raise ValueError(f"reading gestation_positives must be an int in [0, 100000], "
                             f"got {n!r}")  # fmt: skip
        if self.start not in STARTS:
            raise ValueError(f"reading start must be one of {', '.join(STARTS)}, "
                             f"got {self.start!r}")  # fmt: skip
        if self.constrain not in CONSTRAINTS:
            raise ValueError(f"reading constrain must be one of {', '.join(CONSTRAINTS)}, "
                             f"got {self.constrain!r}")  # fmt: skip

    @property
    def name(self) -> str:
        """A short label, e.g. ``pos250-fitted-cstart`` (``-wait``: no one-class fits)."""
        wait = "" if self.one_class_fits else "-wait"
        return f"pos{self.gestation_positives}-{self.start}-c{self.constrain}{wait}"

    @classmethod
    def parse(cls, name: str) -> InitiationReading:
        """The reading of a :attr:`name`; ``ValueError`` naming the bad part otherwise."""
        parts = str(name).split("-")
        if len(parts) not in (3, 4) or not parts[0].startswith("pos") or \
                not parts[2].startswith("c") or (len(parts) == 4 and parts[3] != "wait"):
            raise ValueError(f"reading {name!r} is not of the form pos<N>-<start>-c<when>[-wait]"
                             f" (e.g. pos250-fitted-cstart)")  # fmt: skip
        try:
            n = int(parts[0][3:])
        except ValueError:
            raise ValueError(f"reading {name!r}: pos<N> needs an integer N") from None
        return cls(n, parts[1], parts[2][1:], len(parts) == 3)

    def replace(self, **changes) -> InitiationReading:
        return dataclasses.replace(self, **changes)


# What every run before the readings became parameters used.
FIRST_READING = InitiationReading()
# The trainer's default (results/screening/README.md, 20 runs on the screening seeds): gestation
# positives make the sets local and keep options alive; with options that start from the agent
# (policy_start="top-level", value_start="agent") this reading beat flat agents on episodes
# 51-100, while under the first reading most options died. The library's SkillChaining keeps
# the first reading (the paper's text) as its own default.
DEFAULT_READING = InitiationReading(gestation_positives=20, start="fitted", constrain="start")
