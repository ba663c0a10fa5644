"""A bundle's clips on screen and in its manifest: the summaries each clip shows copied into the bundle, the clips
and reels rendered (or reused where the same summaries, numbers and renderer made them), each clip's audit against
the ground truth (does it visibly show the better robot as better?) and vote, with a warning line where it
misleads, and each clip's manifest entry."""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any, cast

from app.formats import (
    ClipAudit,
    ClipVote,
    Manifest,
    ManifestClip,
    ManifestReel,
    load_summary,
    sha256_file,
)
from app.survey.clip_length import clip_shape
from app.visible import VisibleClip, VisibleReels, World, audit
from search.bundle.evaluations import better_agent
from search.bundle.searches import ClipJob, describe_search
from search.bundle.spec import BuildError
from search.bundle.steps import IN_THIS_PROCESS, Cache, Log, Task, Work, finished
from search.bundle.truth import PairedComparison
from search.clips.render import RenderOptions, RenderResult, agent_label
from search.core.domain import Domain, domain_named, domain_of_summary
from search.solvers.runner import Backend
from search.solvers.solver import solver_named

REEL_HOLD_END = 1.5  # seconds a reel's moment holds its last frame, as a clip's end: a crash at its end reads


def shown_summaries(job: ClipJob, folder: Path, world: World) -> list[list[Path]]:
    """The summaries of a search (in ``folder``) a clip shows: one list holding the clip's summary, or (a pair of
    reels) one list of moments per agent in search order."""
    if not solver_named(job.scheme.solver).reels:
        return [[clip_summary(folder, job.scheme.select, world)]]
    reels = reel_summaries(folder)
    if len(reels) != 2:
        raise BuildError(f"{describe_search(job)}: the search found moments of {len(reels)} of its two agents")
    return reels


def job_summaries(job: ClipJob, folder: Path, out: Path, domain: Domain) -> list[list[Path]]:
    """The summaries a clip shows (`shown_summaries`), copied into the bundle."""
    found = shown_summaries(job, folder, domain.world(job.scenario))
    if len(found) == 1:
        copied = [[out / "summaries" / f"{job.id}.json"]]
    else:
        copied = [
            [out / "summaries" / f"{job.id}.reel{k}-{n}.json" for n in range(1, len(s) + 1)]
            for k, s in enumerate(found)
        ]
    for sources, targets in zip(found, copied, strict=True):
        for source, target in zip(sources, targets, strict=True):
            shutil.copyfile(source, target)
    return copied


def clip_summary(folder: Path, select: str, world: World) -> Path:
    """The summary of a search that becomes the clip: the best by reward, or with ``select = "contrast"`` the one
    of the search's top-K whose clip shows the largest visible difference (no ground truth is read)."""
    from search.core.contrast import largest_contrast

    first = folder / "summary-001.json"
    if select == "reward":
        return first
    paths = sorted(folder.glob("summary-[0-9][0-9][0-9].json"))
    return paths[largest_contrast([dict(load_summary(p)) for p in paths], world)]


def reel_summaries(folder: Path) -> list[list[Path]]:
    """A HIGHLIGHTS search's summaries as one reel per agent (in the search's agent order), moments in order."""
    reels: dict[int, list[Path]] = {}
    for path in sorted(folder.glob("summary-[0-9][0-9][0-9].json")):
        reels.setdefault(load_summary(path)["follow"]["leader"], []).append(path)
    return [reels[k] for k in sorted(reels)]


def render_clips(
    clips: list[tuple[ClipJob, list[Path], Path]],
    options: RenderOptions,
    cache: Cache,
    log: Log,
    backend: Backend = IN_THIS_PROCESS,
) -> None:
    """Render each (job, summaries, clip) on ``backend``, unless the same summaries, numbers, options and
    renderer already made the file there. One summary is a clip; several are one agent's reel of moments."""
    todo: dict[str, Task] = {}
    inputs_of: dict[str, tuple[dict[str, Any], Path]] = {}
    for job, summaries, out in clips:
        domain = domain_of_summary(load_summary(summaries[0]))
        inputs: dict[str, Any] = {
            "summary": sha256_file(summaries[0]) if len(summaries) == 1 else [sha256_file(s) for s in summaries],
            "numbers": list(job.numbers),
            "options": asdict(options if len(summaries) == 1 else moment_options(options)),
            "renderer": [sha256_file(path) for path in domain.renderer_files(summaries[0]) + reel_files(summaries)],
            "clip": out.name,
        }
        folder = cache.path("render", inputs)
        if (
            cache.valid("render", inputs, "sha256")
            and out.is_file()
            and (folder / "sha256").read_text() == sha256_file(out)
        ):
            log(f"render {out.stem}: cached")
            continue
        inputs_of[out.stem] = (inputs, out)
        given = [(path.name, path.read_bytes()) for path in summaries]
        todo[out.stem] = (render_job, (domain.name, given, out.name, list(job.numbers), options))
    for name, ((files, frames), seconds), progress in finished(
        todo, backend, lambda name: f"render {name}", lambda name: Work("clip", 1)
    ):
        inputs, out = inputs_of[name]
        for file, data in files.items():
            (out.parent / file).write_bytes(data)
        folder = cache.store("render", inputs)
        (folder / "sha256").write_text(sha256_file(out))
        cache.seal("render", inputs)
        log(f"render {name}: {frames} frames in {seconds:.1f} s {progress}")


def moment_options(options: RenderOptions) -> RenderOptions:
    """How a reel's moments are drawn: they start at once (the card before each marks the cut) and hold their end
    as a clip does, so an arrival or a crash on a moment's last step stays on screen long enough to read."""
    return replace(options, hold_start=0.0, hold_end=min(options.hold_end, REEL_HOLD_END))


def reel_files(summaries: list[Path]) -> list[Path]:
    """The source of the joining of a reel's moments, where the clip is one."""
    import search.clips.reel as reel

    return [Path(reel.__file__)] if len(summaries) > 1 else []


def render_job(
    domain: str, summaries: list[tuple[str, bytes]], clip: str, numbers: list[int], options: RenderOptions
) -> tuple[tuple[dict[str, bytes], int], float]:
    """Render one clip or reel from its summaries (name, contents) in a folder of its own, as a worker on another
    machine does (the domain is found by name): the files made beside the clip (name -> contents) and its frames,
    and the seconds its rendering took."""
    from search.clips.reel import render_reel

    world = domain_named(domain)
    with tempfile.TemporaryDirectory(prefix="foil-render-") as folder:
        paths, out = [Path(folder) / "summaries" / name for name, _ in summaries], Path(folder) / "clips" / clip
        for path, (_, data) in zip(paths, summaries, strict=True):
            path.parent.mkdir(exist_ok=True)
            path.write_bytes(data)
        result: RenderResult
        if len(paths) == 1:
            result = world.render(paths[0], out, numbers, options)
        else:
            moment = moment_options(options)
            result = render_reel(paths, out, lambda s, o: world.render(s, o, numbers, moment), options)
        files = {path.name: path.read_bytes() for path in sorted(out.parent.iterdir()) if path.is_file()}
    return (files, result.frames), result.render_s


def clip_audit(
    job: ClipJob,
    sources: list[list[Path]],
    evaluations: dict[str, dict[str, Any]],
    shown: World,
    close: dict[tuple[str, str], PairedComparison] | None = None,
) -> tuple[list[str], list[str], dict[str, str]]:
    """A clip's agents and their labels in on-screen order, and what it visibly shows against the ground truth
    (`app.visible.audit`; a pair of reels by each agent's moments)."""
    order = sorted(range(2), key=lambda k: job.numbers[k])
    agents, labels = [job.pair[k] for k in order], [agent_label(shown.words.agent, job.numbers[k]) for k in order]
    if len(sources) == 1:
        visible: VisibleClip | VisibleReels = VisibleClip.of_summary(load_summary(sources[0][0]), agents, labels, shown)
    else:
        segments = [[load_summary(path) for path in sources[k]] for k in order]
        visible = VisibleReels.of_summaries(segments, labels, shown)
    return agents, labels, audit(visible, labels[agents.index(better_agent(job.pair, evaluations, close))])


def manifest_clip(
    job: ClipJob,
    sources: list[list[Path]],
    out: Path,
    evaluations: dict[str, dict[str, Any]],
    shown: World,
    log: Log,
    close: dict[tuple[str, str], PairedComparison] | None = None,
) -> ManifestClip:
    """A clip's manifest entry: agents and labels in on-screen order, ground truth, audit (a warning line when it
    misleads; for a pair the evaluation cannot decide, one that names neither agent as better), what it cost, and
    its file (or each agent's reel)."""
    order = sorted(range(2), key=lambda k: job.numbers[k])
    agents, labels, shown_audit = clip_audit(job, sources, evaluations, shown, close)
    better = better_agent(job.pair, evaluations, close)
    reels = len(sources) > 1
    data: dict[str, Any] = dict(load_summary(sources[0][0]))
    files = [f"clips/{job.id}.reel{k}.mp4" for k in order] if reels else [f"clips/{job.id}.mp4"]
    undecided = [c for c in (close or {}).values() if set(c.agents) == set(job.pair) and not c.decided]
    if shown_audit["shows"] != "better" and undecided:
        log(
            f"warning: clip {job.id} is misleading against a ground truth that rests on a coin toss: "
            f"{job.pair[0]} and {job.pair[1]} differ by less than the evaluation can decide"
        )
    elif shown_audit["shows"] != "better":
        log(
            f"warning: clip {job.id} ({job.scheme.name}, {job.pair[0]} vs {job.pair[1]}) is misleading: it shows "
            f"the better agent as {'no better' if shown_audit['shows'] == 'tie' else 'worse'} (the gallery and "
            "manifest.json say which and why: the log keeps the labels blind for a pilot)"
        )
    vote = clip_vote(data, order)
    solver_says = solver_named(data["solver"]["name"]).clip_warnings(data["solver"])
    for line in [*vote_warnings(agents, None if undecided else better, vote), *solver_says]:
        log(f"warning: clip {job.id} ({job.scheme.name}, {job.pair[0]} vs {job.pair[1]}): {line}")
    spent = {
        "sim_steps": int(data["solver"]["budget_used"]),
        "clip_seconds": sum(clip_shape(out / name).ms for name in files) / 1000,
    }
    common: dict[str, Any] = {
        "id": job.id,
        "scheme": job.scheme.name,
        "scenario": job.scenario,
        "agents": agents,
        "labels": labels,
        "better": better,
        "audit": ClipAudit(**cast(dict[str, Any], shown_audit), vote=vote),  # shows: audit's "better", "worse" or "tie"
        "parts": list(job.parts),
        "solver": job.scheme.solver,
        "spent": spent,
    }
    if reels:
        return ManifestClip(
            **common,
            reels=[
                ManifestReel(
                    agent=job.pair[k],
                    file=name,
                    sha256=sha256_file(out / name),
                    poster=name.removesuffix(".mp4") + ".poster.png",
                    summaries=[str(path.relative_to(out)) for path in sources[k]],
                )
                for k, name in zip(order, files, strict=True)
            ],
        )
    return ManifestClip(
        **common,
        file=files[0],
        sha256=sha256_file(out / files[0]),
        summary=f"summaries/{job.id}.json",
        poster=f"clips/{job.id}.poster.png",
        sheet=f"clips/{job.id}.sheet.png",
        reward=data.get("reward"),
        outcomes=[data["outcomes"][k] for k in order],
    )


def clip_vote(summary: dict[str, Any], order: list[int]) -> ClipVote | None:
    """The vote over starting states that chose a clip, as its solver reads it from the summary
    (`Solver.clip_vote`), each agent's count in on-screen order (``order``: search positions on screen); None for
    clips no vote chose."""
    vote = solver_named(summary["solver"]["name"]).clip_vote(summary["solver"])
    if vote is None:
        return None
    return ClipVote(
        states=vote["states"],
        won=[vote["won"][k] for k in order],
        no_majority=vote["no_majority"],
        p=vote["p"],
        decided=vote["decided"],
        weight=vote["weight"] if order[0] == 0 else -vote["weight"],
    )


def vote_warnings(agents: list[str], better: str | None, vote: ClipVote | None) -> list[str]:
    """What a clip's vote warns of, naming agents (never their labels): a weak vote, and a vote for the agent the
    ground truth ranks worse (``better`` None: no truth to hold it to)."""
    from search.core.contrast import describe_vote

    if vote is None:
        return []
    line = describe_vote(agents, vote["won"], vote["no_majority"], vote["p"])
    found = [] if vote["decided"] else [f"weak vote: {line}; the clip may show either agent as the better one"]
    first, second = vote["won"]
    weight = vote.get("weight", first - second)  # a vote before the weights leaned by its counts
    voted = None if weight == 0 else agents[0] if weight > 0 else agents[1]
    if better is not None and voted is not None and voted != better:
        found.append(f"vote against the ground truth: it favours {voted}, but {better} is better ({line})")
    return found


def clip_files(clip: ManifestClip) -> list[str]:
    """Every file of the bundle a clip needs: its video, poster, contact sheet and summary, or each reel's."""
    if not clip.reels:
        return [clip.file, clip.summary, clip.poster, clip.sheet]
    return [
        path
        for reel in clip.reels
        for path in (reel.file, reel.poster, reel.file.removesuffix(".mp4") + ".sheet.png", *reel.summaries)
    ]


def describe_questions_at_risk(manifest: Manifest) -> list[str]:
    """Per part and scheme, how many questions rest on an undecided ground truth, a weak vote or a misleading
    clip: one line each, a warning where any does (`foil power --bundle` turns the same into expected power)."""
    lines = []
    for row in manifest.questions_at_risk():
        risky = row["undecided"] + row["weak_vote"] + row["misleading"]
        lines.append(
            f"{'warning: ' if risky else ''}{row['part']} part, scheme {row['scheme']}: {row['clips']} clips; "
            f"{row['undecided']} on a pair the evaluation could not decide, {row['weak_vote']} on a weak vote, "
            f"{row['misleading']} visibly showing the worse agent as better or tied"
        )
    return lines
