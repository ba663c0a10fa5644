"""Conditions of a study and balanced assignment of arriving participants to them.

Balance comes from permuted blocks over a counter that lives in the database: each participant who consents
claims the next arrival slot (unique per study, so two processes can never claim the same one) and the slot's place
in its block, shuffled with a generator seeded by the study seed and the block number, names the condition.
Every complete block of arrivals therefore holds each condition exactly once.
"""

from __future__ import annotations

import itertools
import random
from dataclasses import dataclass

from sqlalchemy import Connection, bindparam, func, select
from sqlalchemy.orm import Session

from app.database import Statements
from app.models import Participant
from app.study import Study


@dataclass(frozen=True)
class Condition:
    index: int  # 0-based; participants who pick themselves see index + 1
    schemes: tuple[str, ...]  # the schemes this participant sees, in this order
    rotation: int  # how far the scenarios are rotated across the parts

    def describe(self, study: Study) -> str:
        scenarios = ", ".join(
            f"part {p + 1}: {study.part_scenario(p, self.rotation)}" for p in range(len(study.parts))
        )
        return f"{' then '.join(self.schemes)}; {scenarios}"


def conditions(study: Study) -> list[Condition]:
    design = study.design
    if design.scheme_factor == "between":
        scheme_orders = [(scheme,) for scheme in design.schemes]
    elif design.counterbalance_scheme_order:
        n = len(design.schemes)
        scheme_orders = [tuple(design.schemes[(i + k) % n] for k in range(n)) for i in range(n)]
    else:
        scheme_orders = [tuple(design.schemes)]
    combos = itertools.product(scheme_orders, study.rotations())
    return [Condition(index=i, schemes=s, rotation=r) for i, (s, r) in enumerate(combos)]


def condition_for_slot(*, seed: int, n_conditions: int, slot: int) -> int:
    """Permuted blocks: slot k lands in block k // n, whose order is a seeded shuffle of all conditions."""
    block, place = divmod(slot, n_conditions)
    order = list(range(n_conditions))
    random.Random(f"{seed}:block:{block}").shuffle(order)
    return order[place]


HIGHEST_SLOT = select(func.max(Participant.slot)).where(Participant.study == bindparam("study"))


def next_slot(session: Session | Connection | Statements, *, study: str) -> int:
    """The next free arrival slot. Two concurrent callers may get the same number; the unique constraint on
    (study, slot) lets only one of them commit and the other retries."""
    highest = session.scalar(HIGHEST_SLOT, {"study": study})
    return 0 if highest is None else highest + 1
