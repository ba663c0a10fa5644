"""A participant's plan: the screens they see, in order, built once when their condition is known.

The plan is stored on the participant, so the clip order, the clip variants and the order in which the agents are
offered as answers are recorded and never re-randomised. It holds the ground truth (real agent names, the better
agent), which is why it never leaves the server: pages receive only labels and clip addresses.
"""

from __future__ import annotations

import itertools
import random
from typing import Any

from app.formats import ManifestClip, ManifestReel
from app.survey.assignment import Condition
from app.survey.bundle import Bundle
from app.survey.clip_length import clip_shape
from app.survey.screens import (
    Attention,
    Closing,
    Instructions,
    Option,
    Pairwise,
    Ranking,
    Reel,
    Round,
    Screen,
    Shape,
    Watch,
    WithOptions,
)
from app.survey.study import RankingPart, Study


def _pick(
    bundle: Bundle,
    scheme: str,
    scenario: str,
    pair: tuple[str, str],
    part: str,
    rng: random.Random,
    used: dict[str, str] | None = None,
) -> ManifestClip:
    """One of the clips made for the part (`pairwise` or `ranking`; in id order), at random; where several match,
    preferring one whose labels name no other agent than they already named for this participant (`used`: label
    -> agent)."""
    options = bundle.matching(scheme, scenario, pair, part)
    if used:
        clean = [
            c
            for c in options
            if all(used.get(label, agent) == agent for agent, label in zip(c.agents, c.labels, strict=True))
        ]
        options = clean or options
    return rng.choice(options)


def _shape(bundle: Bundle, sha256: str) -> Shape:
    """A clip's or reel's playing time and picture size, from its file (nothing set for a bundle without its
    files)."""
    path = bundle.paths.get(sha256.lower())
    if path is None:
        return Shape()
    shape = clip_shape(path)
    return Shape(clip_ms=shape.ms, width=shape.width, height=shape.height)


def _options(pairs: list[tuple[str, str]]) -> list[Option]:
    """Answer options as (label, agent) in the order the clips' legends list them, by agent number (the numbers
    are drawn per clip or round when the bundle is built, so no agent is always offered first)."""
    options = [Option(label=label, agent=agent) for agent, label in dict(pairs).items()]
    return sorted(options, key=lambda option: _number(option.label))


def _number(label: str) -> tuple[bool, int]:
    """Sorts a label such as "Agent 7" by its number; a label without one keeps its place after the numbered."""
    last = label.rsplit(" ", 1)[-1]
    numbered = last.isascii() and last.isdigit()
    return (not numbered, int(last) if numbered else 0)


def _clip_fields(
    part_no: int, clip: ManifestClip, questions: list[str], bundle: Bundle, study: Study | None = None
) -> dict[str, Any]:
    """The fields of a pairwise or watch screen showing `clip`: its video, or its reels with their labels; on an
    update pair of the `study`'s design, its later version and whether the two are equal."""
    fields: dict[str, Any] = {
        "part": part_no,
        "clip": clip.id,
        "scheme": clip.scheme,
        "scenario": clip.scenario,
        "robots": _options(list(zip(clip.agents, clip.labels, strict=True))),
        "better": clip.better,
        "questions": questions,
    }
    if clip.reels:
        labelled = zip(clip.reels, clip.labels, strict=True)
        fields |= {"reels": [_reel(bundle, reel, label) for reel, label in labelled]}
    else:
        fields |= {"media": clip.sha256.lower(), **_shape(bundle, clip.sha256).model_dump(exclude_unset=True)}
    update = study.design.update_of(clip.agents) if study is not None else None
    if study is not None and update is not None:
        equal = update in study.design.controls or frozenset(clip.agents) in bundle.undecided
        fields |= {"later": update[1], "equal": equal}
    return fields


def _round_videos(clips: list[ManifestClip]) -> list[str]:
    """The sha256 of each video a ranking page lists: every clip's file (even where two clips share one), and a
    agent's reel once, however often it is paired."""
    videos: list[str] = []
    for clip in clips:
        if not clip.reels:
            videos.append(clip.sha256)
        videos += [reel.sha256 for reel in clip.reels if reel.sha256 not in videos]
    return videos


def _reel(bundle: Bundle, reel: ManifestReel, label: str) -> Reel:
    """A reel as a screen shows it: its agent's label, its file's address and shape."""
    return Reel(label=label, media=reel.sha256.lower(), **_shape(bundle, reel.sha256).model_dump(exclude_unset=True))


def _true_order(clips: list[ManifestClip], agents: list[str]) -> list[str] | None:
    """Best to worst by pairwise wins; None when the clips' `better` values do not give a strict order."""
    wins = {agent: 0 for agent in agents}
    for clip in clips:
        wins[clip.better] += 1
    if len(set(wins.values())) != len(wins):
        return None
    return sorted(agents, key=lambda agent: -wins[agent])


def _ranking_screens(
    part: RankingPart, part_no: int, scheme: str, scenario: str, bundle: Bundle, rng: random.Random, block: int
) -> list[Screen]:
    clips = [_pick(bundle, scheme, scenario, pair, "ranking", rng) for pair in itertools.combinations(part.agents, 2)]
    rng.shuffle(clips)
    screens: list[Screen] = [
        Watch(kind="watch", **_clip_fields(part_no, clip, [], bundle), block=block, round_start=k == 0)
        for k, clip in enumerate(clips)
    ]
    labels = [(agent, label) for clip in clips for agent, label in zip(clip.agents, clip.labels, strict=True)]
    videos = _round_videos(clips)
    screens.append(
        Ranking(
            kind="ranking",
            part=part_no,
            block=block,
            scheme=scheme,
            scenario=scenario,
            clips=[clip.id for clip in clips],
            media_list=[sha.lower() for sha in videos],
            shapes=[_shape(bundle, sha) for sha in videos],
            robots=_options(labels),
            true_order=_true_order(clips, part.agents),
            questions=list(part.questions),
        )
    )
    return screens


def _label_progress(screens: list[Screen], part_no: int, n_parts: int) -> None:
    """What the page says about where the participant is: clips counted per part, or per round of a ranking
    part (the round's clips, then its ranking), as the part's introduction counts them."""
    rounds = sorted({s.block for s in screens if isinstance(s, Round)})
    clips = [s for s in screens if isinstance(s, Pairwise)]
    for screen in screens:
        match screen:
            case Watch() | Ranking():
                in_round = [s for s in screens if isinstance(s, Watch) and s.block == screen.block]
                what = f"round {rounds.index(screen.block) + 1} of {len(rounds)}, "
                what += (
                    f"clip {in_round.index(screen) + 1} of {len(in_round)}" if isinstance(screen, Watch) else "ranking"
                )
            case Pairwise():
                what = f"clip {clips.index(screen) + 1} of {len(clips)}"
            case _:
                what = "a check question"
        screen.progress = f"Part {part_no} of {n_parts}, {what}"


def build_plan(study: Study, bundle: Bundle, condition: Condition, rng: random.Random) -> list[Screen]:
    plan: list[Screen] = [Instructions(kind="instructions")]
    used: dict[str, str] = {}  # label -> the first agent it named for this participant
    for p, part in enumerate(study.parts):
        part_no = p + 1
        scenario = {scheme: study.part_scenario(p, condition.rotation, scheme) for scheme in condition.schemes}
        screens: list[Screen] = []
        if part.kind == "pairwise":
            blocks = [
                [
                    Pairwise(
                        kind="pairwise",
                        **_clip_fields(
                            part_no,
                            _pick(bundle, scheme, scenario[scheme], pair, "pairwise", rng, used),
                            list(part.questions),
                            bundle,
                            study,
                        ),
                    )
                    for pair in part.pairs
                ]
                for scheme in condition.schemes
            ]
            if part.order == "shuffled":
                blocks = [[screen for block in blocks for screen in block]]
            for block in blocks:
                rng.shuffle(block)
                screens += block
        else:
            for b, scheme in enumerate(condition.schemes):
                screens += _ranking_screens(part, part_no, scheme, scenario[scheme], bundle, rng, block=b + 1)
        for c, check in reversed(list(enumerate(study.attention_checks))):
            if check.part == part_no:
                video: dict[str, Any] = {}
                if check.clip is not None:  # a video attention check: its clip, watched like any other
                    clip = bundle.matching(check.clip.scheme, check.clip.scenario, check.clip.agents)[0]
                    video = {
                        "clip": clip.id,
                        "media": clip.sha256.lower(),
                        **_shape(bundle, clip.sha256).model_dump(exclude_unset=True),
                    }
                screen: Screen = Attention(
                    kind="attention",
                    part=part_no,
                    check=c,
                    options=list(check.options),
                    expected=check.expected,
                    **video,
                )
                screens.insert(min(check.after, len(screens)), screen)
        _label_progress(screens, part_no, len(study.parts))
        for screen in screens:
            if isinstance(screen, WithOptions):
                for option in screen.robots:
                    used.setdefault(option.label, option.agent)
        plan += screens
    if study.closing is not None:  # the closing questions and feedback box, after the last part
        plan.append(
            Closing(
                kind="closing",
                questions=list(study.closing.questions),
                feedback=bool(study.closing.feedback),
                progress="Last screen: closing questions",
            )
        )
    for number, screen in enumerate(plan):
        screen.position = (number, len(plan))
    return plan
