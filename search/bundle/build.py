"""`foil bundle STUDY.toml --out DIR`: everything a study serves, built from the study file's `[build]` table.

The table names the agents, scenarios, schemes (a solver with its budget and seed) and sets of clips; each set
says which survey parts its clips feed. The builder evaluates every agent (the ground truth `better`; a pair the
study's episodes cannot tell apart is compared on more paired episodes and named, `search.bundle.truth`), runs
one search per clip (or reuses a cached one whose inputs are unchanged), renders the best summary of each with a
seeded, recorded mapping of agents to robot numbers (no number names two agents anywhere in the bundle), audits
each clip (does it visibly show the better robot as better? judged by the bots' observer, `app.visible`; a
warning line per misleading clip), and writes manifest.json
(`foil.bundle/1`, a sha256 for every file, each clip's `audit`), a copy of the study file and a static index.html
gallery for the researcher, where misleading clips are marked.

This module is the orchestration alone: the study resolved once (`search.bundle.study`), each step a module of its
own, in the order they run: `evaluations` (the ground truth and the close pairs), `searches` (the clips planned and
their searches), `representativeness` (the fixed scenarios' check), `clips` (renders, audits, manifest entries)
and `gallery` (index.html), all over `steps` (the cache, a step's jobs on a backend).

Bundle layout::

    manifest.json  study.toml  index.html
    clips/ID.mp4  clips/ID.poster.png  clips/ID.sheet.png      what participants see (by checksum, never by ID)
    summaries/ID.json                                          the summary each clip shows
    clips/ID.reelK.mp4  summaries/ID.reelK-N.json              a pair of reels (HIGHLIGHTS): agent K's, its moments
    cache/                                                     evaluations and searches, keyed by their inputs
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from app.formats import MANIFEST_FORMAT, ClosePair, Manifest, manifest_json, sha256_file
from search.bundle.clips import clip_files, describe_questions_at_risk, job_summaries, manifest_clip, render_clips
from search.bundle.evaluations import close_pairs, evaluate_agents, shown_pairs, without_episodes
from search.bundle.gallery import write_gallery
from search.bundle.representativeness import representativeness
from search.bundle.searches import ClipJob, plan_clips, run_searches, search_inputs, search_job
from search.bundle.spec import BuildError
from search.bundle.steps import Cache, Log
from search.bundle.study import Study, load_study
from search.core.workers import jobs as spread_over
from search.solvers.runner import Backend, SearchJob, refuse_before_work
from search.solvers.solver import solver_named


@dataclass(frozen=True)
class Prepared:
    """A study's build before any work: its clips, each clip's search and the search's inputs, checked."""

    study: Study
    jobs: list[ClipJob]
    searches: list[SearchJob]
    inputs: list[dict[str, Any]]


def prepare(study: str | os.PathLike[str]) -> Prepared:
    """A study file's build, with bad settings and scenarios refused here, before any work, and a scheme whose
    clip is longer than an episode or whose method needs a capability the world lacks (`refuse_before_work`)."""
    resolved = load_study(study)
    jobs = plan_clips(resolved.spec)
    try:
        searches = [search_job(job, resolved) for job in jobs]
        inputs = [search_inputs(search, resolved.domain) for search in searches]
        for search in {(s.solver, s.agents, s.scenario, repr(s.reward_settings)): s for s in searches}.values():
            refuse_before_work(search)
    except (ValueError, FileNotFoundError) as error:
        raise BuildError(f"{study}: [build]: {error}") from None
    return Prepared(resolved, jobs, searches, inputs)


def build_bundle(
    study: str | os.PathLike[str],
    out: str | os.PathLike[str],
    log: Log = print,
    workers: int = 1,
    backend: str = "process",
    ray_address: str | None = None,
) -> Manifest:
    """Build (or bring up to date) the bundle of a study file in ``out``, its evaluations, searches, checks and
    clips run ``workers`` at a time on ``backend`` (processes here, or Ray tasks on the cluster at
    ``ray_address``); `search.bundle.plan` says beforehand what it will cost. Returns the manifest; its
    files are the same whatever the backend and number of workers."""
    runner = Backend(backend, workers, ray_address)
    prepared = prepare(study)
    resolved, jobs = prepared.study, prepared.jobs
    spec, domain = resolved.spec, resolved.domain
    out = Path(out)
    cache = Cache(out / "cache")
    for folder in ("clips", "summaries"):
        (out / folder).mkdir(parents=True, exist_ok=True)
    log(f"{len(jobs)} clips, {len(spec.agents)} agents")
    with spread_over(workers), runner.session():  # a job run here may spread its own work over the workers
        evaluations = evaluate_agents(resolved, cache, log, runner)
        close = close_pairs(resolved, shown_pairs(jobs), evaluations, cache, log, runner)
        run_searches(list(zip(jobs, prepared.searches, prepared.inputs, strict=True)), cache, log, runner)
        scenario_reports = representativeness(resolved, cache, log, runner)
        sources = {
            job.id: job_summaries(job, cache.path("search", search), out, domain)
            for job, search in zip(jobs, prepared.inputs, strict=True)
        }
        render_clips(clip_renders(jobs, sources, out), spec.render, cache, log, runner)
    clips = [
        manifest_clip(job, sources[job.id], out, evaluations, domain.world(job.scenario), log, close) for job in jobs
    ]
    (out / "study.toml").write_text(resolved.text, encoding="utf-8")
    wanted = {path for c in clips for path in clip_files(c)} | {"study.toml"}
    for stale in [*(out / "clips").iterdir(), *(out / "summaries").iterdir()]:
        if str(stale.relative_to(out)) not in wanted:
            stale.unlink()
    compared = [comparison.to_manifest() for comparison in close.values()]
    write_gallery(out, clips, evaluations, scenario_reports, resolved.shows, compared)
    manifest = Manifest(
        format=MANIFEST_FORMAT,
        label_seed=spec.seed,
        clips=clips,
        agents={agent: without_episodes(evaluation) for agent, evaluation in evaluations.items()},
        sources={agent: domain.agent_source(agent, resolved.world) for agent in spec.agents},
        files={name: sha256_file(out / name) for name in sorted(wanted | {"index.html"})},
        representativeness=scenario_reports,
        world=resolved.shows.to_manifest(),  # the crowd's is left out (`Manifest`): a reader assumes it
        close_pairs=[ClosePair.model_validate(pair) for pair in compared],
    )
    (out / "manifest.json").write_text(manifest_json(manifest), encoding="utf-8")
    for line in describe_questions_at_risk(manifest):
        log(line)
    log(f"bundle {out}: {len(clips)} clips; manifest.json, index.html")
    return manifest


def clip_renders(
    jobs: list[ClipJob], sources: dict[str, list[list[Path]]], out: Path
) -> list[tuple[ClipJob, list[Path], Path]]:
    """What to render for each clip, as (job, summaries, file): its clip, or one reel per agent."""
    renders = []
    for job in jobs:
        if solver_named(job.scheme.solver).reels:
            renders += [
                (job, paths, out / "clips" / f"{job.id}.reel{k}.mp4") for k, paths in enumerate(sources[job.id])
            ]
        else:
            renders.append((job, sources[job.id][0], out / "clips" / f"{job.id}.mp4"))
    return renders
