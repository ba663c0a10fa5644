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

Bundle layout::

    manifest.json  study.toml  index.html
    clips/ID.mp4  clips/ID.poster.png  clips/ID.sheet.png      what participants see (by checksum, never by ID)
    summaries/ID.json                                          the summary each clip shows
    clips/ID.reelK.mp4  summaries/ID.reelK-N.json              a pair of reels (HIGHLIGHTS): agent K's, its moments
    cache/                                                     evaluations and searches, keyed by their inputs
"""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import random
import shutil
import tempfile
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from app.formats import (
    MANIFEST_FORMAT,
    ClipAudit,
    ClipVote,
    ClosePair,
    Manifest,
    ManifestClip,
    ManifestReel,
    load_summary,
    manifest_json,
    sha256_file,
)
from app.survey.clip_length import clip_shape
from app.visible import VisibleClip, VisibleReels, World, audit
from search.bundle.spec import BuildError, BuildSpec, Scheme, load_build
from search.bundle.truth import PairedComparison, compare_pairs, describe_close_pair
from search.clips.render import RenderOptions, agent_label
from search.core.workers import jobs as spread_over
from search.solvers.domain import Domain, domain_for, domain_named, domain_of_summary
from search.solvers.runner import Backend, SearchJob, run_search, write_outputs
from search.solvers.solver import solver_named
from search.solvers.summary import verify

IN_THIS_PROCESS = Backend()  # one worker: every job of a step in the building process


@dataclass(frozen=True)
class ClipJob:
    """One clip: the pair in search order (the summary's agents) and each one's robot number on screen."""

    id: str
    scheme: Scheme
    scenario: str
    pair: tuple[str, str]
    numbers: tuple[int, int]
    parts: tuple[str, ...]


def plan_clips(spec: BuildSpec) -> list[ClipJob]:
    """Every clip of the study with its robot numbers. Numbers are handed out in blocks and never twice: a block
    of two per clip, or, in a set that feeds a ranking, one per scheme and scenario (a round) with one number per
    agent across its clips. So a participant never sees one name (colour, shape) stand for two agents, whichever
    clips their plan shows, and a round's robots keep theirs. Which agent gets which number of its block is drawn
    from a seeded generator named after the clip or round."""
    jobs, first = [], 1
    for i, clip_set in enumerate(spec.sets):
        for scheme, scenario in itertools.product(clip_set.schemes, clip_set.scenarios):
            group = f"{spec.seed}/{i}/{scheme}/{scenario}"
            if clip_set.ranking:
                block = range(first, first + len(clip_set.agents))
                first += len(block)
                shared = dict(zip(clip_set.agents, random.Random(group).sample(block, len(block)), strict=True))
            for pair in clip_set.pairs:
                name = f"{group}/{pair[0]}/{pair[1]}"
                if clip_set.ranking:
                    numbers = tuple(shared[a] for a in pair)
                else:
                    numbers, first = tuple(random.Random(name).sample([first, first + 1], 2)), first + 2
                for parts, suffix, drawn in _draws(spec.schemes[scheme], clip_set.parts):
                    jobs.append(
                        ClipJob(
                            id="clip-" + hashlib.sha256(f"{name}{suffix}".encode()).hexdigest()[:10],
                            scheme=drawn,
                            scenario=scenario,
                            pair=pair,
                            numbers=numbers,
                            parts=parts,
                        )
                    )
    return jobs


def _draws(scheme: Scheme, parts: tuple[str, ...]) -> list[tuple[tuple[str, ...], str, Scheme]]:
    """The clips of a set's pair under a scheme, as (parts fed, suffix of the clip's name, scheme): one for all the
    set's parts. A solver that starts only from a distribution (the representative solver) draws its starting
    states at random, so a set feeding both parts gets a draw of its own (seed + 1) for the ranking, whose round
    would otherwise replay part one's clips."""
    if solver_named(scheme.solver).starts != "distribution" or not {"pairwise", "ranking"} <= set(parts):
        return [(parts, "", scheme)]
    ranking = replace(scheme, seed=scheme.seed + 1)
    return [(tuple(part for part in parts if part != "ranking"), "", scheme), (("ranking",), "/ranking", ranking)]


def input_key(inputs: dict) -> str:
    return hashlib.sha256(json.dumps(inputs, sort_keys=True).encode()).hexdigest()[:16]


def study_domain(spec: BuildSpec) -> Domain:
    """The one world of a study, from its agents and a scenario (an agent given as module:attribute may act in
    any world)."""
    return domain_for(spec.agents, spec.sets[0].scenarios[0], spec.world)


def agent_identity(agent: str, domain: Domain) -> dict:
    """What an agent's results depend on: its name and, for a network, the checksum of its file."""
    path = domain.agent_file(agent)
    return {"agent": agent, "sha256": sha256_file(path)} if path is not None and path.is_file() else {"agent": agent}


def search_job(job: ClipJob, world: dict | None = None, named: str | None = None) -> SearchJob:
    """The search behind a clip, with its scheme's settings; ``world`` is the study's comparison world
    (``study_world``), under the scenario file's and the scheme's world settings; ``named`` the world the study
    names, if it does."""
    scheme, domain = job.scheme, domain_for(job.pair, job.scenario, named)
    world = under(world, domain.scenario_settings(job.scenario) if world else {})
    return SearchJob(
        agents=job.pair,
        scenario=job.scenario,
        solver=scheme.solver,
        budget=scheme.budget,
        seed=scheme.seed,
        top_k=scheme.top_k,
        solver_config=scheme.solver_config,
        reward_settings=scheme.reward.to_dict(),
        world_settings=world | scheme.world,
        world=named,
    )


def study_world(spec: BuildSpec) -> dict:
    """The world settings a study compares its agents in: those its imported checkpoints were trained in (a
    CrowdNav_DSRNN model's config), for every agent, in the evaluation and in every search alike."""
    return study_domain(spec).agents_settings(spec.agents)


def under(world: dict | None, own: dict) -> dict:
    """The study's ``world`` settings that a scenario's ``own`` settings leave as they are."""
    return {key: value for key, value in (world or {}).items() if key not in own}


def beneath(scenario, world: dict | None):
    """A scenario or distribution with the study's ``world`` settings beneath its own."""
    world = under(world, scenario.world)
    return replace(scenario, world=world | scenario.world) if world else scenario


def search_inputs(search: SearchJob) -> dict:
    """Everything a clip's search depends on, with every default resolved, so a changed default is a changed
    input."""
    from search.solvers.reward import RewardConfig

    domain = domain_for(search.agents, search.scenario, search.world)
    return {
        "agents": [agent_identity(a, domain) for a in search.agents],
        "scenario": domain.scenario_dict(search.scenario, search.world_settings),
        "solver": search.solver,
        "solver_settings": asdict(search.solver_config),
        "reward": RewardConfig(**search.reward_settings).to_dict(),
        "budget": search.budget,
        "seed": search.seed,
        "top_k": search.top_k,
    }


class Cache:
    """Results kept under ``root`` by a hash of their inputs, with the inputs beside them to check on reuse."""

    def __init__(self, root: Path):
        self.root = root

    def path(self, kind: str, inputs: dict) -> Path:
        return self.root / kind / input_key(inputs)

    def valid(self, kind: str, inputs: dict, *files: str) -> bool:
        folder = self.path(kind, inputs)
        try:
            recorded = json.loads((folder / "inputs.json").read_text())
        except (OSError, json.JSONDecodeError):
            return False
        return recorded == json.loads(json.dumps(inputs)) and all((folder / f).is_file() for f in files)

    def store(self, kind: str, inputs: dict) -> Path:
        """A fresh, empty folder for a result; write the result, then call ``seal``."""
        folder = self.path(kind, inputs)
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir(parents=True)
        return folder

    def seal(self, kind: str, inputs: dict) -> None:
        """Record the inputs last, so an interrupted build never leaves a result that looks complete."""
        (self.path(kind, inputs) / "inputs.json").write_text(json.dumps(inputs, sort_keys=True, indent=1))


def evaluate_agents(
    spec: BuildSpec, domain: Domain, cache: Cache, log, world: dict | None = None, backend: Backend = IN_THIS_PROCESS
) -> dict[str, dict]:
    """Each agent's `foil eval --json` object on the study's episodes (the manifest's ground truth) in the ``world``
    settings, with its per-episode rewards where the world gives them (`Domain.evaluate_episodes`)."""
    found = evaluate_runs(
        spec, domain, cache, log, [(agent, spec.eval_episodes) for agent in spec.agents], world, backend
    )
    return {agent: found[agent, spec.eval_episodes] for agent in spec.agents}


def evaluate_runs(
    spec: BuildSpec,
    domain: Domain,
    cache: Cache,
    log,
    runs: list[tuple[str, int]],
    world: dict | None,
    backend: Backend,
) -> dict[tuple[str, int], dict]:
    """Each (agent, episodes)'s evaluation at the study's eval seed, computed once per input on ``backend``."""
    inputs_of, todo = {}, {}
    for run, (inputs, task) in eval_tasks(spec, domain, runs, world).items():
        inputs_of[run] = inputs
        if cache.valid("eval", inputs, "eval.json"):
            log(f"eval {_run_name(spec, *run)}: cached")
        else:
            todo[run] = task
    described = {run: f"eval {_run_name(spec, *run)}" for run in todo}
    for run, (result, seconds), progress in finished(todo, backend, described.get):
        folder = cache.store("eval", inputs_of[run])
        (folder / "eval.json").write_text(json.dumps(result, indent=1))
        cache.seal("eval", inputs_of[run])
        log(
            f"{described[run]}: reward {result['reward_mean']:.2f}, success {result['success_rate']:.2f} "
            f"({seconds:.1f} s) {progress}"
        )
    return {
        run: json.loads((cache.path("eval", inputs) / "eval.json").read_text()) for run, inputs in inputs_of.items()
    }


def eval_tasks(
    spec: BuildSpec, domain: Domain, runs: list[tuple[str, int]], world: dict | None
) -> dict[tuple[str, int], tuple[dict, tuple]]:
    """Each (agent, episodes)'s inputs and job (function, arguments); in a world whose agents act in their
    scenario's world, in the first scenario they are shown in."""
    seed, world, found = spec.eval_seed, world or {}, {}
    for agent, episodes in runs:
        shown = [name for clip_set in spec.sets if agent in clip_set.agents for name in clip_set.scenarios]
        scenario = domain.eval_scenario(shown)
        inputs = {"agent": agent_identity(agent, domain), "episodes": episodes, "seed": seed, "per_episode": True} | (
            {"world": world} if world else {}
        )
        if scenario is not None:
            inputs["scenario"] = domain.scenario_dict(scenario, world)
        found[agent, episodes] = (inputs, (evaluation_job, (domain.name, agent, episodes, seed, world, scenario)))
    return found


def _run_name(spec: BuildSpec, agent: str, episodes: int) -> str:
    return agent if episodes == spec.eval_episodes else f"{agent} on {episodes} episodes"


def finished(tasks: dict, backend: Backend, describe) -> Iterator[tuple[Any, Any, str]]:
    """Run a step's ``tasks`` on ``backend``: (key, result, progress) as each finishes, its progress the jobs done
    of the step's and, at the pace so far, the time left ("[3/8, about 2 min left]"), for a long step's log."""
    started = time.perf_counter()
    for done, (key, result) in enumerate(backend.run(tasks, describe), start=1):
        left = (time.perf_counter() - started) / done * (len(tasks) - done)
        yield key, result, f"[{done}/{len(tasks)}" + (f", about {duration(left)} left]" if done < len(tasks) else "]")


def duration(seconds: float) -> str:
    """A length of time as a person reads it: 40 s, 12 min, 2 h 5 min."""
    if seconds < 90:
        return f"{max(1, round(seconds))} s"
    minutes = round(seconds / 60)
    return f"{minutes} min" if minutes < 90 else f"{minutes // 60} h {minutes % 60} min"


def evaluation_job(domain: str, agent: str, episodes: int, seed: int, world: dict, scenario: str | None):
    """One agent's evaluation and the seconds it took (in a worker process: the domain is found by name)."""
    started = time.perf_counter()
    result = domain_named(domain).evaluate_episodes(agent, episodes, seed, world, scenario) | {"agent": agent}
    return result, time.perf_counter() - started


def close_pairs(
    spec: BuildSpec,
    pairs: list[tuple[str, str]],
    evaluations: dict[str, dict],
    domain: Domain,
    cache: Cache,
    log,
    world: dict | None = None,
    backend: Backend = IN_THIS_PROCESS,
) -> dict[tuple[str, str], PairedComparison]:
    """The pairs shown together that the study's own episodes cannot tell apart, each compared on more paired
    episodes until decided or at the cap (`search.bundle.truth`), with a line each (a warning for an undecided
    one, naming agents only). Pairs decided on the study's episodes are left out: their truth is as before."""
    if any("episode_rewards" not in evaluations[agent] for pair in pairs for agent in pair):
        return {}  # a world without per-episode rewards: mean rewards alone

    def rewards(wanted: set[tuple[str, int]]) -> dict[tuple[str, int], list[float]]:
        more = sorted(run for run in wanted if run[1] != spec.eval_episodes)  # the first look's are in hand
        found = evaluate_runs(spec, domain, cache, log, more, world, backend) if more else {}
        found |= {(agent, n): evaluations[agent] for agent, n in wanted if n == spec.eval_episodes}
        return {run: result["episode_rewards"] for run, result in found.items()}

    compared = compare_pairs(pairs, spec.eval_episodes, rewards)
    close = {pair: c for pair, c in compared.items() if c.episodes > spec.eval_episodes or not c.decided}
    for comparison in close.values():
        log(describe_close_pair(comparison))
    return close


def shown_pairs(jobs: list[ClipJob]) -> list[tuple[str, str]]:
    """Every pair of agents some clip shows together, once, in the order of the first clip showing it."""
    pairs: list[tuple[str, str]] = []
    for job in jobs:
        if job.pair not in pairs and job.pair[::-1] not in pairs:
            pairs.append(job.pair)
    return pairs


def without_episodes(evaluation: dict) -> dict:
    """An evaluation as `foil eval --json` prints it, for the manifest: without its per-episode rewards."""
    return {key: value for key, value in evaluation.items() if key != "episode_rewards"}


def _describe(job: ClipJob) -> str:
    return f"search {job.scheme.name} {job.scenario} {job.pair[0]}-{job.pair[1]}"


def _reusable(job: ClipJob, inputs: dict, cache: Cache, log) -> bool:
    """A cached search is reused while its inputs are unchanged and its summary still re-simulates exactly
    (`foil verify`), so changes to the simulator or the policies' code are caught too."""
    if not cache.valid("search", inputs, "summary-001.json"):
        return False
    problems = verify(cache.path("search", inputs) / "summary-001.json")
    if problems:
        log(f"{_describe(job)}: the cached summary no longer re-simulates exactly ({problems[0]}); searching again")
        return False
    log(f"{_describe(job)}: cached")
    return True


def search_job_files(search: SearchJob) -> tuple[dict[str, str], float]:
    """One search's files (`run_search`) and the seconds it took."""
    started = time.perf_counter()
    return run_search(search), time.perf_counter() - started


def run_searches(
    jobs: list[tuple[ClipJob, SearchJob, dict]], cache: Cache, log, backend: Backend = IN_THIS_PROCESS
) -> None:
    """Run every search the cache cannot supply on ``backend``; each result is written and sealed in the cache as
    soon as it is complete, so an interrupted build keeps the finished ones."""
    todo = {}
    for job, search, inputs in jobs:
        if input_key(inputs) not in todo and not _reusable(job, inputs, cache, log):
            todo[input_key(inputs)] = (job, search, inputs)

    tasks = {key: (search_job_files, (search,)) for key, (_, search, _) in todo.items()}
    for key, (files, seconds), progress in finished(tasks, backend, lambda key: _describe(todo[key][0])):
        job, _, inputs = todo[key]
        write_outputs(cache.store("search", inputs), files)
        cache.seal("search", inputs)
        log(f"{_describe(job)}: {seconds:.1f} s {progress}")


def better_agent(
    pair: tuple[str, str], evaluations: dict[str, dict], close: dict[tuple[str, str], PairedComparison] | None = None
) -> str:
    """The ground truth: the agent with the higher mean test reward (the paper ranks its agents by it); for a close
    pair, over the most paired episodes it was evaluated on."""
    comparison = (close or {}).get(pair) or (close or {}).get(pair[::-1])
    if comparison is not None:  # the mean paired difference, first minus second
        pair, (first, second) = comparison.agents, (comparison.difference, 0.0)
    else:
        first, second = (evaluations[a]["reward_mean"] for a in pair)
    if first == second:
        raise BuildError(f"{pair[0]} and {pair[1]} have the same mean reward; no better agent to record")
    return pair[0] if first > second else pair[1]


def render_clips(
    clips: list[tuple[ClipJob, list[Path], Path]],
    options: RenderOptions,
    cache: Cache,
    log,
    backend: Backend = IN_THIS_PROCESS,
):
    """Render each (job, summaries, clip) on ``backend``, unless the same summaries, numbers, options and
    renderer already made the file there. One summary is a clip; several are one agent's reel of moments."""
    todo, inputs_of = {}, {}
    for job, summaries, out in clips:
        domain = domain_of_summary(load_summary(summaries[0]))
        inputs = {
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
    for name, (files, frames), progress in finished(todo, backend, lambda name: f"render {name}"):
        inputs, out = inputs_of[name]
        for file, data in files.items():
            (out.parent / file).write_bytes(data)
        folder = cache.store("render", inputs)
        (folder / "sha256").write_text(sha256_file(out))
        cache.seal("render", inputs)
        log(f"render {name}: {frames} {progress}")


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
) -> tuple[dict[str, bytes], str]:
    """Render one clip or reel from its summaries (name, contents) in a folder of its own, as a worker on another
    machine does (the domain is found by name): the files made beside the clip (name -> contents) and what it
    took, for the log."""
    from search.clips.reel import render_reel

    world = domain_named(domain)
    with tempfile.TemporaryDirectory(prefix="foil-render-") as folder:
        paths, out = [Path(folder) / "summaries" / name for name, _ in summaries], Path(folder) / "clips" / clip
        for path, (_, data) in zip(paths, summaries, strict=True):
            path.parent.mkdir(exist_ok=True)
            path.write_bytes(data)
        if len(paths) == 1:
            result = world.render(paths[0], out, numbers, options)
        else:
            moment = moment_options(options)
            result = render_reel(paths, out, lambda s, o: world.render(s, o, numbers, moment), options)
        files = {path.name: path.read_bytes() for path in sorted(out.parent.iterdir()) if path.is_file()}
    return files, f"{result.frames} frames in {result.render_s:.1f} s"


def reel_summaries(folder: Path) -> list[list[Path]]:
    """A HIGHLIGHTS search's summaries as one reel per agent (in the search's agent order), moments in order."""
    reels: dict[int, list[Path]] = {}
    for path in sorted(folder.glob("summary-[0-9][0-9][0-9].json")):
        reels.setdefault(load_summary(path)["follow"]["leader"], []).append(path)
    return [reels[k] for k in sorted(reels)]


@dataclass(frozen=True)
class Prepared:
    """A study's build before any work: its clips, each clip's search and the search's inputs, checked."""

    spec: BuildSpec
    text: str
    jobs: list[ClipJob]
    world: dict
    searches: list[SearchJob]
    inputs: list[dict]


def prepare(study: str | os.PathLike) -> Prepared:
    """A study file's build, with bad settings and scenarios refused here, before any work."""
    spec, text = load_build(study)
    jobs = plan_clips(spec)
    try:
        world = study_world(spec)
        searches = [search_job(job, world, spec.world) for job in jobs]
        inputs = [search_inputs(search) for search in searches]
    except (ValueError, FileNotFoundError) as error:
        raise BuildError(f"{study}: [build]: {error}") from None
    return Prepared(spec, text, jobs, world, searches, inputs)


def build_bundle(
    study: str | os.PathLike,
    out: str | os.PathLike,
    log=print,
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
    spec, jobs, world = prepared.spec, prepared.jobs, prepared.world
    out = Path(out)
    cache = Cache(out / "cache")
    for folder in ("clips", "summaries"):
        (out / folder).mkdir(parents=True, exist_ok=True)
    log(f"{len(jobs)} clips, {len(spec.agents)} agents")
    domain = study_domain(spec)
    with spread_over(workers), runner.session():  # a job run here may spread its own work over the workers
        evaluations = evaluate_agents(spec, domain, cache, log, world, runner)
        close = close_pairs(spec, shown_pairs(jobs), evaluations, domain, cache, log, world, runner)
        run_searches(list(zip(jobs, prepared.searches, prepared.inputs, strict=True)), cache, log, runner)
        scenario_reports = representativeness(spec, cache, log, world, runner)
        sources = {
            job.id: job_summaries(job, cache.path("search", search), out, domain)
            for job, search in zip(jobs, prepared.inputs, strict=True)
        }
        renders = []
        for job in jobs:
            if solver_named(job.scheme.solver).reels:
                renders += [
                    (job, paths, out / "clips" / f"{job.id}.reel{k}.mp4") for k, paths in enumerate(sources[job.id])
                ]
            else:
                renders.append((job, sources[job.id][0], out / "clips" / f"{job.id}.mp4"))
        render_clips(renders, spec.render, cache, log, runner)
    clips = [
        manifest_clip(job, sources[job.id], out, evaluations, domain.world(job.scenario), log, close) for job in jobs
    ]
    (out / "study.toml").write_text(prepared.text, encoding="utf-8")
    wanted = {path for c in clips for path in clip_files(c)} | {"study.toml"}
    for stale in [*(out / "clips").iterdir(), *(out / "summaries").iterdir()]:
        if str(stale.relative_to(out)) not in wanted:
            stale.unlink()
    compared = [comparison.to_manifest() for comparison in close.values()]
    write_gallery(out, clips, evaluations, scenario_reports, compared)
    study_shows = domain.world(spec.sets[0].scenarios[0])  # the crowd's words are the default: left out
    manifest = Manifest(
        format=MANIFEST_FORMAT,
        label_seed=spec.seed,
        clips=clips,
        agents={agent: without_episodes(evaluation) for agent, evaluation in evaluations.items()},
        sources={agent: domain.agent_source(agent, world or {}) for agent in spec.agents},
        files={name: sha256_file(out / name) for name in sorted(wanted | {"index.html"})},
        representativeness=scenario_reports,
        world=None if study_shows == World() else study_shows.to_manifest(),
        close_pairs=[ClosePair.model_validate(pair) for pair in compared],
    )
    (out / "manifest.json").write_text(manifest_json(manifest), encoding="utf-8")
    for line in describe_questions_at_risk(manifest):
        log(line)
    log(f"bundle {out}: {len(clips)} clips; manifest.json, index.html")
    return manifest


REEL_HOLD_END = 1.5  # seconds a reel's moment holds its last frame, as a clip's end: a crash at its end reads


def shown_summaries(job: ClipJob, folder: Path, world: World) -> list[list[Path]]:
    """The summaries of a search (in ``folder``) a clip shows: one list holding the clip's summary, or (a pair of
    reels) one list of moments per agent in search order."""
    if not solver_named(job.scheme.solver).reels:
        return [[clip_summary(folder, job.scheme.select, world)]]
    reels = reel_summaries(folder)
    if len(reels) != 2:
        raise BuildError(f"{_describe(job)}: the search found moments of {len(reels)} of its two agents")
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


def clip_audit(
    job: ClipJob,
    sources: list[list[Path]],
    evaluations: dict[str, dict],
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
    evaluations: dict[str, dict],
    shown: World,
    log,
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
    for line in vote_warnings(agents, None if undecided else better, vote):
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
        "audit": ClipAudit(**shown_audit, vote=vote),
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


def clip_vote(summary: dict, order: list[int]) -> ClipVote | None:
    """The representative solver's vote as a clip's summary records it, each agent's count in on-screen order
    (``order``: search positions on screen); None for other clips."""
    vote = summary["solver"].get("vote")
    if vote is None:
        return None
    won = [vote["for_first"], vote["for_second"]]
    return ClipVote(
        states=vote["states"],
        won=[won[k] for k in order],
        no_majority=vote["no_majority"],
        sign_test_p=vote["sign_test_p"],
        decided=vote["decided"],
    )


def vote_warnings(agents: list[str], better: str | None, vote: ClipVote | None) -> list[str]:
    """What a clip's vote warns of, naming agents (never their labels): a weak vote, and a vote for the agent the
    ground truth ranks worse (``better`` None: no truth to hold it to)."""
    from search.solvers.representative import describe_vote

    if vote is None:
        return []
    line = describe_vote(agents, vote["won"], vote["no_majority"], vote["sign_test_p"])
    found = [] if vote["decided"] else [f"weak vote: {line}; the clip may show either agent as the better one"]
    first, second = vote["won"]
    voted = None if first == second else agents[0] if first > second else agents[1]
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


def clip_summary(folder: Path, select: str, world: World) -> Path:
    """The summary of a search that becomes the clip: the best by reward, or with ``select = "contrast"`` the one
    of the search's top-K whose clip shows the largest visible difference (no ground truth is read)."""
    from search.solvers.representative import largest_contrast

    first = folder / "summary-001.json"
    if select == "reward":
        return first
    paths = sorted(folder.glob("summary-[0-9][0-9][0-9].json"))
    return paths[largest_contrast([dict(load_summary(p)) for p in paths], world)]


def representativeness(
    spec: BuildSpec, cache: Cache, log, world: dict | None = None, backend: Backend = IN_THIS_PROCESS
) -> list[dict]:
    """For every pair shown on a fixed scenario in a pairwise or ranking part: how often each agent looks better
    there under nominal pushes, against the vote of the task's distribution (`[build.representativeness]`, by
    default the world's own), with a warning line when the scenario's majority disagrees with the distribution's
    vote; pairs measured on ``backend``. ``world`` is the study's comparison world (``study_world``),
    beneath each scenario's and the distribution's own settings."""
    from search.solvers.representative import strength

    checks = check_tasks(spec, world)
    todo = {
        pair: task
        for pair, (_, _, inputs, task) in checks.items()
        if not cache.valid("representativeness", inputs, "report.json")
    }
    described = {pair: f"representativeness {pair[0]}-{pair[1]}" for pair in todo}
    for pair, (found, seconds), progress in finished(todo, backend, described.get):
        folder = cache.store("representativeness", checks[pair][2])
        (folder / "report.json").write_text(json.dumps(found, indent=1))
        cache.seal("representativeness", checks[pair][2])
        log(f"{described[pair]}: {seconds:.1f} s {progress}")
    reports = []
    for pair, (names, distribution, inputs, _) in checks.items():
        found = json.loads((cache.path("representativeness", inputs) / "report.json").read_text())
        for name, one in zip(names, found, strict=True):
            report = {"agents": list(pair), "scenario": name, "distribution": distribution} | {
                key: value for key, value in one.items() if key != "scenario"
            }
            vote = report["distribution_vote"]  # a report cached before votes had their sign test gets it here
            report["distribution_vote"] = vote | strength(vote["for_first"], vote["for_second"])
            reports.append(report)
            log(describe_representativeness(report))
    return reports


def check_tasks(spec: BuildSpec, world: dict | None) -> dict[tuple[str, str], tuple[list[str], str, dict, tuple]]:
    """Each pair shown on a fixed scenario in a pairwise or ranking part, with its scenarios, the distribution
    they are measured against, the check's inputs and its job (function, arguments); none in a world with no
    distribution of starting states where the study names none."""
    from search.solvers.reward import RewardConfig

    settings = spec.representativeness
    scenarios_of: dict[tuple[str, str], list[str]] = {}
    for clip_set in spec.sets:
        if {"pairwise", "ranking"} & set(clip_set.parts):
            for pair, name in itertools.product(clip_set.pairs, clip_set.scenarios):
                if not domain_for(pair, name, spec.world).is_distribution(name):
                    scenarios_of.setdefault(pair, []).append(name)
    checks = {}
    for pair, names in scenarios_of.items():
        domain = domain_for(pair, names[0], spec.world)
        distribution = settings.distribution or domain.default_distribution
        if distribution is None:
            continue  # a world with no distribution of starting states, and none named in the study
        names = list(dict.fromkeys(names))
        fixed = [domain.state(name, under(world, domain.scenario_settings(name))) for name in names]
        drawn_world = under(world, domain.scenario_settings(distribution))
        inputs = {
            "agents": [agent_identity(a, domain) for a in pair],
            "scenarios": [s.to_dict() for s in fixed],
            "distribution": domain.scenario_dict(distribution, drawn_world),
            "states": settings.states,
            "pushes": settings.pushes,
            "seed": settings.seed,
            "reward": RewardConfig().to_dict(),
        }
        task = (_representativeness, (domain.name, pair, fixed, distribution, drawn_world, settings))
        checks[pair] = (names, distribution, inputs, task)
    return checks


def _representativeness(domain_name: str, pair, fixed: list, distribution: str, world: dict, settings):
    """One pair's representativeness reports and the seconds they took (in a worker process: the domain is
    found by name)."""
    import numpy as np

    from search.solvers.representative import RepresentativeConfig
    from search.solvers.representative import representativeness as measure
    from search.solvers.reward import RewardConfig

    started, domain, reward = time.perf_counter(), domain_named(domain_name), RewardConfig().to_dict()
    rng = np.random.default_rng(settings.seed)
    drawn = domain.draw_states(distribution, world, rng, settings.states)
    found = measure(
        lambda states, pushes, rng, tracker: domain.roll_out(pair, states, reward, pushes, rng, tracker),
        fixed,
        drawn,
        RepresentativeConfig(states=settings.states, pushes=settings.pushes),
        rng,
    )
    return found, time.perf_counter() - started


def describe_representativeness(report: dict) -> str:
    """One line on a fixed scenario against the distribution, a warning when their majorities disagree; a weak
    distribution vote (its sign test not below alpha) is called weak, since it cannot say which agent most states
    show as better."""
    from search.solvers.representative import strength

    first, second = report["agents"]
    vote = report["distribution_vote"]
    voted = {1: first, -1: second, 0: "neither"}[vote["direction"]]
    tested = strength(vote["for_first"], vote["for_second"])  # one look, at the default alpha
    p = tested["sign_test_p"]
    line = (
        f"{report['scenario']}, {first} vs {second}: {first} looks better in {report['first_looks_better']:.0%} "
        f"of {report['rollouts']} nominal rollouts, {second} in {report['second_looks_better']:.0%}; "
        f"{report['distribution']}'s {vote['states']} states vote {voted} ({vote['for_first']} for {first}, "
        f"{vote['for_second']} for {second}), sign test p {'< 0.001' if p < 0.001 else f'= {p:.2g}'}"
    )
    if report["percentile"] is not None:
        line += (
            f"; it agrees with that vote more often than {report['percentile']:.0f}% of the distribution's states do "
            f"(percentile {report['percentile']:.0f}; low: an unusual scenario for a pair)"
        )
    weak = (
        ""
        if tested["decided"]
        else f"; a weak vote (p not below {tested['alpha']}): too few or too evenly split states to say which agent "
        f"most starting states show as better"
    )
    if report["disagrees"] and report["majority"] == 0:
        return (
            f"warning: unrepresentative scenario {line}: its clips tend to show no difference where most "
            f"starting states show one{weak}"
        )
    if report["disagrees"]:
        return (
            f"warning: unrepresentative scenario {line}: its clips tend to show the other agent as better than "
            f"most starting states do{weak}"
        )
    return f"representativeness {line}{weak}"


def write_gallery(
    out: Path,
    clips: list[ManifestClip],
    evaluations: dict[str, dict],
    scenario_reports: list[dict],
    close: list[dict] | None = None,
) -> None:
    """A static page of every clip with what participants never see: agents, ground truth, outcomes, reward, and
    the close pairs (manifest `close_pairs`), whose undecided ones no clip marks a better agent for."""
    from jinja2 import Environment, FileSystemLoader, StrictUndefined

    from search.solvers.representative import describe_vote

    templates = Environment(
        loader=FileSystemLoader(Path(__file__).parent),
        autoescape=True,
        undefined=StrictUndefined,
        keep_trailing_newline=True,
    )
    page = templates.get_template("gallery.html").render(
        clips=clips,
        evaluations=evaluations,
        zip=zip,
        scenarios=scenario_reports,
        describe=describe_representativeness,
        describe_vote=describe_vote,
        vote_warnings=vote_warnings,
        close=close or [],
        describe_close=lambda pair: describe_close_pair(PairedComparison.from_manifest(pair)),
    )
    (out / "index.html").write_text(page, encoding="utf-8")
