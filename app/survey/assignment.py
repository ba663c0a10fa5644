"""Conditions of a study and balanced assignment of arriving participants to them.

Balance comes from permuted blocks over a counter that lives in the database: each participant who consents
claims the next arrival slot (unique per study, so two processes can never claim the same one) and the slot's place
in its block, shuffled with a generator seeded by the study seed and the block number, names the condition.
Every complete block of arrivals therefore holds each condition exactly once. Arrivals, not completions: a slot
is never released, so a participant who leaves keeps theirs and completions per condition can differ by the
abandoned slots (the admin overview counts them per condition).
"""

from __future__ import annotations

import hashlib
import itertools
import random
from dataclasses import dataclass

from sqlalchemy import Connection, Dialect, bindparam, func, select
from sqlalchemy.orm import Session

from app.store.models import Participant
from app.survey.study import PairwisePart, Study


@dataclass(frozen=True)
class Condition:
    index: int  # 0-based; participants who pick themselves see index + 1
    schemes: tuple[str, ...]  # the schemes this participant sees, in this order
    rotation: int  # how far the scenarios are rotated across the parts

    def describe(self, study: Study) -> str:
        """Per part, the schemes in the order it shows them (a pairwise part that shuffles its clips mixes the
        schemes; a ranking part has a round per scheme in turn) and the scenarios it shows them on."""
        parts = []
        for p, part in enumerate(study.parts):
            mixed = isinstance(part, PairwisePart) and part.order == "shuffled" and len(self.schemes) > 1
            order = f"{', '.join(self.schemes)} shuffled together" if mixed else " then ".join(self.schemes)
            scenarios = dict.fromkeys(study.part_scenario(p, self.rotation, scheme) for scheme in self.schemes)
            parts.append(f"part {p + 1}: {order} on {', '.join(scenarios)}")
        return "; ".join(parts)


def conditions(study: Study) -> list[Condition]:
    design = study.design
    if design.scheme_factor == "between":
        scheme_orders: list[tuple[str, ...]] = [(scheme,) for scheme in design.schemes]
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
ARRIVALS_TURN = select(func.pg_advisory_xact_lock(bindparam("key")))


def next_slot(session: Session | Connection, *, study: str) -> int:
    """The next free arrival slot, in a write transaction that then saves the participant with it. Arrivals take
    turns, so two are never handed the same slot: on PostgreSQL the transaction first takes an advisory lock of
    the study's arrivals (held until it commits, across processes), on SQLite its BEGIN IMMEDIATE already waits
    for any other writer. The unique constraint on (study, slot) stays as the last safeguard."""
    if _dialect(session).name == "postgresql":
        key = int.from_bytes(hashlib.sha256(f"foil arrivals {study}".encode()).digest()[:8], "big", signed=True)
        session.scalar(ARRIVALS_TURN, {"key": key})
    highest = session.scalar(HIGHEST_SLOT, {"study": study})
    return 0 if highest is None else highest + 1


def _dialect(session: Session | Connection) -> Dialect:
    return session.get_bind().dialect if isinstance(session, Session) else session.dialect
