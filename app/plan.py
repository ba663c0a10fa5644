"""A participant's plan: the screens they see, in order, built once when their condition is known.

The plan is stored on the participant, so the clip order, the clip variants and the order in which the robots are
offered as answers are recorded and never re-randomised. It holds the ground truth (real agent names, the better
agent), which is why it never leaves the server: pages receive only labels and clip addresses.
"""

from __future__ import annotations

import itertools
import random

from app.assignment import Condition
from app.bundle import Bundle, ManifestClip
from app.study import RankingPart, Study


def _pick(bundle: Bundle, scheme: str, scenario: str, pair: tuple[str, str], rng: random.Random) -> ManifestClip:
    return rng.choice(bundle.matching(scheme, scenario, pair))  # in id order


def _robots(pairs: list[tuple[str, str]], rng: random.Random) -> list[dict]:
    """Answer options as (label, agent), in a random order so that no robot is always offered first."""
    robots = [{"label": label, "agent": agent} for agent, label in dict(pairs).items()]
    rng.shuffle(robots)
    return robots


def _clip_screen(kind: str, part_no: int, clip: ManifestClip, questions: list[str], rng: random.Random) -> dict:
    return {
        "kind": kind,
        "part": part_no,
        "clip": clip.id,
        "media": clip.sha256.lower(),
        "scheme": clip.scheme,
        "scenario": clip.scenario,
        "robots": _robots(list(zip(clip.agents, clip.labels, strict=True)), rng),
        "better": clip.better,
        "questions": questions,
    }


def _true_order(clips: list[ManifestClip], agents: list[str]) -> list[str] | None:
    """Best to worst by pairwise wins; None when the clips' `better` values do not give a strict order."""
    wins = {agent: 0 for agent in agents}
    for clip in clips:
        wins[clip.better] += 1
    if len(set(wins.values())) != len(wins):
        return None
    return sorted(agents, key=lambda agent: -wins[agent])


def _ranking_screens(part: RankingPart, part_no: int, scheme: str, scenario: str, bundle: Bundle,
                     rng: random.Random, block: int) -> list[dict]:
    clips = [_pick(bundle, scheme, scenario, pair, rng) for pair in itertools.combinations(part.agents, 2)]
    rng.shuffle(clips)
    screens = [_clip_screen("watch", part_no, clip, [], rng) | {"block": block} for clip in clips]
    labels = [(agent, label) for clip in clips for agent, label in zip(clip.agents, clip.labels, strict=True)]
    screens.append({
        "kind": "ranking",
        "part": part_no,
        "block": block,
        "scheme": scheme,
        "scenario": scenario,
        "clips": [clip.id for clip in clips],
        "robots": _robots(labels, rng),
        "true_order": _true_order(clips, part.agents),
        "questions": list(part.questions),
    })
    return screens


def _label_progress(screens: list[dict], part_no: int, n_parts: int) -> None:
    clips = [s for s in screens if "media" in s]
    rankings = [s for s in screens if s["kind"] == "ranking"]
    for screen in screens:
        if "media" in screen:
            what = f"clip {clips.index(screen) + 1} of {len(clips)}"
        elif screen["kind"] == "ranking":
            what = f"ranking {rankings.index(screen) + 1} of {len(rankings)}"
        else:
            what = "a check question"
        screen["progress"] = f"Part {part_no} of {n_parts}, {what}"


def build_plan(study: Study, bundle: Bundle, condition: Condition, rng: random.Random) -> list[dict]:
    plan: list[dict] = [{"kind": "instructions"}]
    for p, part in enumerate(study.parts):
        part_no = p + 1
        scenario = study.part_scenario(p, condition.rotation)
        screens: list[dict] = []
        if part.kind == "pairwise":
            blocks = [
                [_clip_screen("pairwise", part_no, _pick(bundle, scheme, scenario, tuple(pair), rng),
                              list(part.questions), rng) for pair in part.pairs]
                for scheme in condition.schemes
            ]
            if part.order == "shuffled":
                blocks = [[screen for block in blocks for screen in block]]
            for block in blocks:
                rng.shuffle(block)
                screens += block
        else:
            for b, scheme in enumerate(condition.schemes):
                screens += _ranking_screens(part, part_no, scheme, scenario, bundle, rng, block=b + 1)
        for c, check in reversed(list(enumerate(study.attention_checks))):
            if check.part == part_no:
                screens.insert(min(check.after, len(screens)), {
                    "kind": "attention", "part": part_no, "check": c,
                    "options": list(check.options), "expected": check.expected,
                })
        _label_progress(screens, part_no, len(study.parts))
        plan += screens
    return plan
