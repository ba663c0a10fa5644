"""The analysis tests' world: a bundle the bots can judge (every clip its own file with a summary.json saying what
it shows, one of them misleading), participants written straight into a database with real plans, and a textbook
Fisher exact test to check the report against."""

from __future__ import annotations

import json
import math
import random
import subprocess
from pathlib import Path

import imageio_ffmpeg

from app.formats import SUMMARY_FORMAT, Manifest, ManifestClip, ManifestReel, manifest_json, sha256_file
from app.store.database import Database
from app.store.models import Participant, Response
from app.survey.assignment import conditions
from app.survey.bundle import load_bundle
from app.survey.clip_length import clip_shape
from app.survey.plan import build_plan
from app.survey.screens import dump_plan, parse_plan
from tests.support.survey import AGENT_RANK, SECRET_NAMES, WATCHED, make_clip, watched_reels, write_bundle

SCHEMES = [SECRET_NAMES["adaptive"], SECRET_NAMES["nfirst"]]
SCENARIOS = [SECRET_NAMES["paper-bl-tr"], SECRET_NAMES["paper-tl-br"]]
EXAMPLE = (SECRET_NAMES["nfirst"], SECRET_NAMES["paper-code"], (SECRET_NAMES["lo"], SECRET_NAMES["hi"]))
# What each agent visibly does in the clips: the best one reaches the goal soonest, the worst one collides.
SHOWN = {
    SECRET_NAMES["hi"]: {"event": "success", "time": 9.0, "min_other_distance": 0.6},
    SECRET_NAMES["med"]: {"event": "success", "time": 16.0, "min_other_distance": 0.4},
    SECRET_NAMES["lo"]: {"event": "collision", "time": 6.0, "min_other_distance": 0.0},
}
# One clip where the worse robot looks better (its search found a scenario where `lo` does well): an observer
# who judges what it sees gets it wrong, one who read the ground truth would not.
MISLEADING = f"{SECRET_NAMES['nfirst']}-{SCENARIOS[0]}-{SECRET_NAMES['lo']}-{SECRET_NAMES['hi']}"


def summary_for(agents: list[str], misleading: bool) -> dict:
    """A small summary.json of two robots (in `agents` order) walking from (-4, -4) to (4, 4)."""
    outcomes = [dict(SHOWN[agent]) for agent in agents]
    if misleading:
        outcomes = [
            {"event": "timeout", "time": 20.0, "min_other_distance": 0.5}
            if agent == SECRET_NAMES["hi"]
            else {"event": "success", "time": 8.0, "min_other_distance": 0.9}
            for agent in agents
        ]
    steps = [
        {
            "t": round(0.25 * (k + 1), 2),
            "other_positions": [[0.0, 1.0]],
            "agent_positions": [[-4 + 0.3 * k, -4 + 0.3 * k]] * 2,
            "agent_actions": [[0.3, 0.3]] * 2,
        }
        for k in range(80)
    ]
    return {
        "format": SUMMARY_FORMAT,
        "agents": [{"name": a, "source": a} for a in agents],
        "scenario": {"robot": {"start": [-4.0, -4.0], "goal": [4.0, 4.0]}},
        "steps": steps,
        "outcomes": outcomes,
        "reward": 1.0,
        "reward_terms": {},
    }


def write_bot_bundle(folder: Path, root: Path, seconds: float = 1) -> Path:
    """The paper study's bundle in `root` with a distinct clip file (same picture, different metadata) per entry,
    each with its summary and playing `seconds`; `folder` holds the clips made on the way."""
    base = folder / "base.mp4"
    make_clip(base, "testsrc", seconds=seconds)
    n_clips = len(SCHEMES) * len(SCENARIOS) * 3 + 1
    files = []
    for n in range(n_clips):
        files.append(folder / f"{n:03d}.mp4")
        distinct_copy(base, files[-1], f"clip {n}")
    root = write_bundle(root, files, schemes=SCHEMES, scenarios=SCENARIOS, agents=AGENT_RANK, example=EXAMPLE)
    manifest = json.loads((root / "manifest.json").read_text())
    (root / "summaries").mkdir()
    for clip in manifest["clips"]:
        (root / clip["summary"]).write_text(json.dumps(summary_for(clip["agents"], clip["id"] == MISLEADING)))
    return root


def distinct_copy(source: Path, target: Path, comment: str) -> None:
    """The same picture as `source` in a file of its own (its metadata says `comment`): the bots know a clip by its
    file's sha256."""
    subprocess.run(
        [
            imageio_ffmpeg.get_ffmpeg_exe(),
            "-v",
            "error",
            "-y",
            "-i",
            str(source),
            "-c",
            "copy",
            "-metadata",
            f"comment={comment}",
            str(target),
        ],
        check=True,
    )


def segment_summary(agents: list[str], leader: str) -> dict:
    """A segment of `leader`'s reel: `summary_for` the robots `agents` (each as it does in SHOWN), with every robot
    following `leader` throughout, so the segment shows the leader's outcome and not the others'."""
    summary = summary_for(agents, misleading=False)
    return summary | {"follow": {"leader": agents.index(leader), "steps": len(summary["steps"])}}


def add_reels(root: Path, reel: Path) -> Path:
    """The bundle in `root` (written by `write_bundle`) with a pair of reels for every clip the study's parts show,
    made for the pairwise part, so every pairwise screen shows reels (the coupled clips serve the ranking part and
    the example). Each robot's reel is a copy of `reel` of its own with two segments, in which the other robot
    comes first and follows it: read right (by `follow.leader`), its visible score is what SHOWN says of it."""
    manifest = Manifest.model_validate_json((root / "manifest.json").read_text())
    (root / "reels").mkdir(exist_ok=True)
    (root / "summaries").mkdir(exist_ok=True)
    clips = []
    for clip in manifest.clips:
        if clip.scenario == EXAMPLE[1]:
            clips.append(clip)
            continue
        clips.append(clip.model_copy(update={"parts": ["ranking"]}))
        reels = []
        for k, agent in enumerate(clip.agents):
            other = clip.agents[1 - k]
            file = f"reels/{clip.id}-{k}.mp4"
            distinct_copy(reel, root / file, f"{clip.id} reel {k}")
            segments = []
            for n in range(2):
                segments.append(f"summaries/{clip.id}-reel{k}-{n}.json")
                (root / segments[-1]).write_text(json.dumps(segment_summary([other, agent], agent)))
            reels.append(ManifestReel(agent=agent, file=file, sha256=sha256_file(root / file), summaries=segments))
        clips.append(
            ManifestClip(
                id=f"{clip.id}-reels",
                scheme=clip.scheme,
                scenario=clip.scenario,
                agents=clip.agents,
                labels=clip.labels,
                better=clip.better,
                parts=["pairwise"],
                reels=reels,
                spent={"sim_steps": 1000, "clip_seconds": 2 * clip_shape(reel).ms / 1000},
            )
        )
    (root / "manifest.json").write_text(manifest_json(manifest.model_copy(update={"clips": clips})))
    return root


def add_participant(
    db: Database,
    study,
    bundle_root: Path,
    *,
    condition: int,
    answer,
    status: str = "completed",
    seed: int = 0,
    minutes: float = 10.0,
    excluded: bool = False,
) -> Participant:
    """A participant with a real plan (app.survey.plan) and `answer(screen) -> answers dict` for every screen."""
    from datetime import UTC, datetime, timedelta

    bundle = load_bundle(bundle_root)
    with db.writing() as session:
        number = session.query(Participant).count()
        start = datetime(2024, 5, 1, 12, 0, tzinfo=UTC) + timedelta(hours=number)
        participant = Participant(
            code=f"hand{number:03d}",
            study=study.study.id,
            platform="none",
            status=status,
            condition=condition,
            created_at=start,
            excluded=excluded,
            completed_at=start + timedelta(minutes=minutes) if status == "completed" else None,
        )
        session.add(participant)
        session.flush()
        participant.plan = dump_plan(build_plan(study, bundle, conditions(study)[condition], random.Random(seed)))
        for step, (screen, typed) in enumerate(zip(participant.plan, parse_plan(participant.plan), strict=True)):
            answers = answer(screen)
            clips = len(typed.clips_to_watch())  # what a browser records: each clip played to its end
            events = [] if not clips else json.loads(WATCHED if clips == 1 else watched_reels(list(range(clips))))
            if screen["kind"] == "attention" and answers["attention"] != screen["expected"]:
                participant.attention_failures += 1
            session.add(
                Response(
                    participant_id=participant.id,
                    step=step,
                    kind=screen["kind"],
                    answers=answers,
                    video_events=events,
                    plays=sum(event["type"] == "play" for event in events),
                    client_ms=1000 + step,
                    server_ms=900 + step,
                    submitted_at=start + timedelta(seconds=10 * step),
                )
            )
        participant.step = len(participant.plan)
    return participant


def label_of(screen: dict, agent: str) -> str:
    return next(robot["label"] for robot in screen["robots"] if robot["agent"] == agent)


def fisher_two_sided(a: int, b: int, c: int, d: int) -> float:
    """Sum of the hypergeometric probabilities of every table with the same margins no more likely than this one."""
    row1, col1, n = a + b, a + c, a + b + c + d

    def prob(x: int) -> float:
        return math.comb(col1, x) * math.comb(n - col1, row1 - x) / math.comb(n, row1)

    observed = prob(a)
    low, high = max(0, row1 + col1 - n), min(row1, col1)
    return sum(prob(x) for x in range(low, high + 1) if prob(x) <= observed * (1 + 1e-7))
