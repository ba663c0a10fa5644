"""The part of a summary a clip shows and the leader its agents followed, read alike by every world's renderer.

A summary may say which part a clip shows and whether the agents followed a leader (the summaries of Agent
Disagreements and HIGHLIGHTS, docs/clips.md): ``window = [first, last]`` keeps the states s_first..s_last (s_0 is
the initial state, s_i the one after step i) with the clock restarted at s_first, and ``follow = {leader, steps}``
either leaves the leader alone (it was followed throughout: the others are where it is) or marks the moment the
agents part (s_steps, when it lies in the window).
"""

from __future__ import annotations


class SummaryError(ValueError):
    """A summary file that cannot be shown; the message names the file and the part that is wrong."""


def window_of(summary: dict, states: int, source: str = "summary") -> tuple[int, int]:
    """A summary's ``window`` as (first, last) state indices (``states`` states after the initial one); the whole
    clip without one."""
    value = summary.get("window")
    if value is None:
        return 0, states
    if (
        isinstance(value, list)
        and len(value) == 2
        and all(isinstance(v, int) and not isinstance(v, bool) for v in value)
        and 0 <= value[0] < value[1] <= states
    ):
        return value[0], value[1]
    raise SummaryError(
        f"{source}: window must be [first, last] with 0 <= first < last <= {states} (the states a clip shows), "
        f"got {value!r}"
    )


def follow_of(summary: dict, agents: int, source: str = "summary") -> tuple[int, int] | None:
    """A summary's ``follow`` as (leader, steps): every agent took the leader's action on steps 1..steps."""
    value = summary.get("follow")
    if value is None:
        return None
    leader, steps = (value.get("leader"), value.get("steps")) if isinstance(value, dict) else (None, None)
    if (
        isinstance(leader, int)
        and isinstance(steps, int)
        and not isinstance(leader, bool)
        and not isinstance(steps, bool)
        and 0 <= leader < agents
        and steps >= 0
    ):
        return leader, steps
    raise SummaryError(
        f"{source}: follow must be {{leader, steps}} with a leader from 0 to {agents - 1} and steps >= 0, got {value!r}"
    )
