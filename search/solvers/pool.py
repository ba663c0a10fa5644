"""Rollouts shared by every pair that reads them: the starting states drawn from one distribution, each played once
by every agent of a study's representative searches (or of one search's pair), however many pairs, parts and
checks read them.

An agent's rollout from a state under a push sequence depends on no other agent (`search.core.contrast.Played`),
so a pool plays all its agents together, a batch of states at a time, and a pair's rollouts are read from theirs
(`Played.pair`). Everything a pool draws is its own and keyed, never a stream that pairs share in turn: the states
and pushes at each clip length come from a generator of their own (`keyed_rng`), a batch's pushes are drawn in
order when the batch is first played, and a fixed scenario's from a generator named after it. So a pair's votes read
the same whichever agents are pooled with it, however many states other pairs used, and alone as in a study.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from search.core.contrast import Played, RollOut, Rollouts
from search.core.rollout import Tracker

if TYPE_CHECKING:
    from search.core.domain import Domain

FIXED = 1 << 30  # spawn keys of fixed scenarios' generators start here, above every clip length's


def keyed_rng(rng: np.random.Generator, key: int) -> np.random.Generator:
    """The generator of ``rng``'s seed for one use, by its ``key`` (a clip length in steps, or a fixed scenario's
    name's), the same however much of ``rng`` has been drawn."""
    seeds = rng.bit_generator.seed_seq
    assert isinstance(seeds, np.random.SeedSequence)
    return np.random.default_rng(np.random.SeedSequence(seeds.entropy, spawn_key=(*seeds.spawn_key, key)))


class Pool:
    """Every agent's rollouts of the states drawn from ``scenario`` (a distribution) in ``world``, and of any fixed
    state asked for, under ``reward`` (its end rule made ``finish = "last"``; its horizon set per clip length),
    ``pushes`` pushed rollouts besides one without per state, played ``batch_states`` states at a time. The
    generators are ``rng``'s seed's (`keyed_rng`): a search's pool and a study's give the same draws."""

    def __init__(
        self,
        domain: Domain,
        agents: Sequence[str],
        scenario: str,
        world: dict[str, Any],
        reward: dict[str, Any],
        states: int,
        pushes: int,
        batch_states: int,
        rng: np.random.Generator,
    ) -> None:
        if len(set(agents)) != len(agents):
            raise ValueError(f"a pool plays each agent once; {list(agents)} names one twice")
        self.domain, self.agents, self.scenario, self.world = domain, list(agents), scenario, world
        self.reward = reward | {"finish": "last"}
        self.states, self.pushes, self.batch_states, self.rng = states, pushes, batch_states, rng
        self.drawn: dict[int, tuple[list[Any], np.random.Generator]] = {}  # a length's states and generator
        self.batches: dict[tuple[int, int], Played] = {}  # (length, batch): every agent's rollouts
        self.fixed_played: dict[tuple[str, int], Played] = {}
        self.played_steps = 0  # steps every agent played, one per agent and step

    def draw(self, horizon: int) -> list[Any]:
        """The states drawn for clips of ``horizon`` steps (drawn once)."""
        if horizon not in self.drawn:
            rng = keyed_rng(self.rng, horizon)
            self.drawn[horizon] = (self.domain.draw_states(self.scenario, self.world, rng, self.states), rng)
        return self.drawn[horizon][0]

    def rollouts(self, pair: Sequence[str], horizon: int) -> RollOut:
        """The pair's rollouts of the states drawn for ``horizon``, read in order from the first on, a batch or
        its first states at a time (as `search.solvers.representative.roll_out_states` asks; each rollout's state
        counted from the first asked for), counted against the tracker as the pair's own steps."""
        first, second = (self.agents.index(agent) for agent in pair)
        drawn, read = self.draw(horizon), [0]  # the states read so far

        def roll_out(states: list[Any], tracker: Tracker) -> Rollouts:
            start, end = read[0], read[0] + len(states)
            if states != drawn[start:end]:
                raise ValueError("a pool's states are read in order, from the first on")
            read[0] = end
            size, parts = self.batch_states, []
            for index in range(start // size, (end - 1) // size + 1):  # the batches that hold them
                low = max(start - index * size, 0)
                part = self.batch(horizon, index).states(low, end - index * size)
                part.state += index * size + low - start
                parts.append(part)
            found, steps = Played.join(parts).pair(first, second)
            tracker.count(steps)
            return found

        return roll_out

    def batch(self, horizon: int, index: int) -> Played:
        """Every agent's rollouts of batch ``index`` of the states drawn for ``horizon``, played once: the batches
        before it first, so each batch's pushes are the same draws however the pool is read."""
        if (horizon, index) not in self.batches:
            if index and (horizon, index - 1) not in self.batches:
                self.batch(horizon, index - 1)
            states, rng = self.draw(horizon), self.drawn[horizon][1]
            chosen = states[index * self.batch_states : (index + 1) * self.batch_states]
            self.batches[horizon, index] = self.play(chosen, horizon, rng)
        return self.batches[horizon, index]

    def fixed(self, name: str, state: Any, horizon: int) -> Played:
        """Every agent's rollouts of one fixed state (a study's scenario ``name``), its pushes drawn from a
        generator named after it."""
        if (name, horizon) not in self.fixed_played:
            rng = keyed_rng(self.rng, FIXED + zlib.crc32(f"{name}/{horizon}".encode()) % FIXED)
            self.fixed_played[name, horizon] = self.play([state], horizon, rng)
        return self.fixed_played[name, horizon]

    def play(self, states: list[Any], horizon: int, rng: np.random.Generator) -> Played:
        """Every agent's rollouts of ``states`` to ``horizon`` steps, pushes from ``rng``, their steps counted."""
        played = self.domain.play_states(self.agents, states, self.reward | {"horizon": horizon}, self.pushes, rng)
        self.played_steps += sum(
            int(np.where(ends > 0, ends, len(env)).sum()) for ends, env in zip(played.ends, played.env, strict=True)
        )
        return played
