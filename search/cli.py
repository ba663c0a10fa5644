"""The `foil` command line: the offline side's commands here, the survey server's from app/cli.py. Each subcommand
imports its machinery only when it runs, so a server-only install (without the `search` extra) runs the server's
commands and refuses the offline ones with the extra to install."""

from __future__ import annotations

import argparse
import json
import math
import sys
import warnings
from collections.abc import Callable
from functools import partial
from importlib.util import find_spec
from pathlib import Path
from typing import Any

from app.cli import COMMANDS as SERVER_COMMANDS
from app.cli import add_commands as add_server_commands
from app.cli import comma_separated
from search.solvers.solver import DEFAULT_SOLVER

# What the `search` extra adds to a server-only install (pyproject.toml), by import name: every offline command
# needs it.
OFFLINE_MODULES = ("numpy", "numba", "torch", "gymnasium", "tqdm", "imageio_ffmpeg", "PIL")


def _train(args: argparse.Namespace) -> int:
    from search.core.domain import trainer_for

    print(f"last checkpoint: {trainer_for(Path(args.config)).train(Path(args.config), Path(args.out))}")
    return 0


def _release(args: argparse.Namespace) -> int:
    from search.core.domain import trainer_for

    trainer = trainer_for(args.run_dir)
    if args.validate_only:
        trainer.validate_run(args.run_dir, args.episodes, args.every)
    else:
        print(json.dumps(trainer.release(args.run_dir, args.out, args.episodes, args.every, args.jobs), indent=1))
    return 0


def _eval(args: argparse.Namespace) -> int:
    from search.core.domain import domain_for
    from search.core.workers import jobs

    domain = domain_for([args.agent], args.scenario)
    world = domain.parse_world(args.world)
    if args.time_limit is not None:
        if not (math.isfinite(args.time_limit) and args.time_limit > 0):
            raise ValueError(f"--time-limit must be a positive, finite number of seconds, got {args.time_limit}")
        if domain.episode_seconds_setting is None:
            raise ValueError(
                f"--time-limit sets an episode's length in a world with a setting for it; in the {domain.name} world "
                "an episode ends when its environment says so (give one of its own settings with --world instead)"
            )
        world[domain.episode_seconds_setting] = args.time_limit
    with jobs(args.jobs):
        result = domain.evaluate(args.agent, args.episodes, args.seed, world, args.scenario) | {"agent": args.agent}
    print(json.dumps(result) if args.json else domain.describe_evaluation(result))
    return 0


def _render(args: argparse.Namespace) -> int:
    from app.formats import load_summary
    from search.clips.render import RenderOptions
    from search.core.domain import domain_of_summary

    options = RenderOptions(fps=args.fps, speed=args.speed, width=args.width, crf=args.crf)
    data = load_summary(args.summary)
    numbers = [int(n) for n in args.numbers.split(",")] if args.numbers else list(range(1, len(data["agents"]) + 1))
    result = domain_of_summary(data).render(Path(args.summary), Path(args.out), numbers, options)
    print(
        f"{result.clip}: {result.frames} frames, {result.seconds:.1f} s, {result.width}x{result.height}, "
        f"rendered in {result.render_s:.2f} s; poster {result.poster.name}, contact sheet {result.sheet.name}"
    )
    return 0


def _bundle(args: argparse.Namespace) -> int:
    from search.bundle.build import build_bundle, prepare
    from search.bundle.plan import plan_lines
    from search.bundle.steps import Cache
    from search.core.workers import workers
    from search.solvers.runner import Backend

    count = workers() if args.jobs is None else args.jobs
    if args.pilot:
        from search.bundle.pilot import pilot_lines

        backend = Backend(args.backend, count, args.ray_address)
        for line in pilot_lines(prepare(args.study), Cache(Path(args.out) / "cache"), backend):
            print(line, flush=True)
        return 0
    if args.plan:
        Backend(args.backend, count, args.ray_address)  # refuses bad settings as a build would
        for line in plan_lines(prepare(args.study), Cache(Path(args.out) / "cache"), count):
            print(line)
        return 0
    build_bundle(args.study, args.out, workers=count, backend=args.backend, ray_address=args.ray_address)
    return 0


def _search_job_settings(args: argparse.Namespace, solver: str, agents: list[str], scenario: str) -> dict:
    """A search job's settings from the command line: the solver's lengths of time in seconds by default, each
    converted by the scenario's step length (``--set horizon_steps=N`` gives steps)."""
    from search.core.domain import domain_for
    from search.core.settings import in_steps
    from search.solvers.reward import RewardConfig
    from search.solvers.runner import parse_settings
    from search.solvers.solver import solver_named

    config_class = solver_named(solver).config_class
    domain = domain_for(agents, scenario)
    world = domain.parse_world(args.world)
    given = parse_settings(config_class, args.set, "solver")
    return {
        "budget": args.budget,
        "seed": args.seed,
        "top_k": args.top_k,
        "solver_config": config_class(
            **in_steps(config_class, given, domain.step_seconds(scenario, world), defaults=True)
        ),
        "reward_settings": in_steps(
            RewardConfig, parse_settings(RewardConfig, args.reward, "reward"), domain.step_seconds(scenario, world)
        ),
        "world_settings": world,
    }


def _search(args: argparse.Namespace) -> int:
    from search.core.workers import jobs
    from search.solvers.runner import SearchJob, refuse_before_work, run_search, write_outputs
    from search.solvers.solver import solver_named

    agents = comma_separated(args.agents)
    job = SearchJob(
        agents=tuple(agents),
        scenario=args.scenario,
        solver=args.solver,
        **_search_job_settings(args, args.solver, agents, args.scenario),
    )
    refuse_before_work(job)
    with jobs(args.jobs):
        files = run_search(job, progress=not args.quiet)
    out = write_outputs(args.out, files)
    print(f"{out}: {len(list(out.glob('summary-*.json')))} summaries, best first; run.json has the search record")
    if not any(name.startswith("summary-") for name in files):
        print(
            f"warning: {out}: no trajectory ended within the budget of {job.budget} steps: raise --budget (or, for "
            "a solver with a batch setting, lower it)"
        )
    for warning in solver_named(job.solver).warnings(json.loads(files["run.json"])):
        print(f"warning: {out}: {warning}")
    return 0


def _search_all(args: argparse.Namespace) -> int:
    from search.solvers.runner import run_all, study_jobs

    solvers, agents, scenarios = (comma_separated(a) for a in (args.solvers, args.agents, args.scenarios))
    if len(solvers) > 1 and args.set:
        raise ValueError("--set applies to one solver: give a single --solvers with it")
    jobs = [
        job
        for solver in solvers
        for job in study_jobs(
            agents, scenarios, [solver], joint=args.joint, **_search_job_settings(args, solver, agents, scenarios[0])
        )
    ]
    if args.jobs is not None and args.jobs < 1:
        raise ValueError(f"--jobs must be at least 1, got {args.jobs}")
    study = run_all(
        jobs, args.out, workers=args.jobs, backend=args.backend, ray_address=args.ray_address, progress=not args.quiet
    )
    print(f"{args.out}: {len(jobs)} searches in {study['wall_s']:.1f} s; study.json lists them")
    for record in study["jobs"]:
        if "warning" in record:
            print(f"warning: {Path(args.out) / record['dir']}: {record['warning']}")
    return 0


def _verify(args: argparse.Namespace) -> int:
    from search.solvers.summary import verify

    failed = 0
    for path in args.summaries:
        problems = verify(path)
        failed += bool(problems)
        print(f"{path}: " + ("reproduced exactly" if not problems else "DIFFERS\n  " + "\n  ".join(problems)))
    return 1 if failed else 0


def _worlds(args: argparse.Namespace) -> int:
    from search.core.domain import domains
    from search.core.world import Trainer

    for domain in domains():
        trains = "; foil train and foil release make its agents" if isinstance(domain, Trainer) else ""
        print(f"{domain.name}: {domain.describe_agents()}{trains}")
        shipped = domain.shipped_scenarios()
        for kind, drawn in (("scenarios", False), ("distributions of starting states", True)):
            if names := [name for name in shipped if domain.is_distribution(name) == drawn]:
                print(f"  shipped {kind}: {', '.join(names)}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="foil",
        description="Contrasting behaviour summaries of agent policies, and the user study that tests them.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    train = sub.add_parser(
        "train",
        help="train a world's own agents from a config file (resumes a run found in --out); foil worlds says "
        "which worlds have a trainer",
    )
    train.add_argument("--config", required=True, help="TOML file of training settings (see docs/agents.md)")
    train.add_argument("--out", required=True, help="run directory: progress.csv and checkpoints/")
    train.set_defaults(handler=_train)

    release = sub.add_parser(
        "release",
        help="choose lo, med and hi from a training run and write their "
        "checkpoints and model cards (see docs/agents.md)",
    )
    release.add_argument("run_dir", metavar="RUN_DIR", type=Path, help="the run directory of foil train")
    release.add_argument(
        "--out",
        type=Path,
        help="where the checkpoints and cards go (default: the shipped agents' folder of the installed package)",
    )
    release.add_argument("--episodes", type=int, default=500, help="validation and test episodes (default 500)")
    release.add_argument("--every", type=int, default=2, help="validate every N-th checkpoint (default 2)")
    release.add_argument("--validate-only", action="store_true", help="print the validation curve, ship nothing")
    release.add_argument(
        "--jobs",
        type=int,
        default=1,
        help="test the chosen agents in this many processes, where the world can (default 1)",
    )
    release.set_defaults(handler=_release)

    worlds = sub.add_parser("worlds", help="the installed worlds, the agents and scenarios each ships")
    worlds.set_defaults(handler=_worlds)

    evaluate = sub.add_parser("eval", help="success, collision and timeout rates and mean reward of an agent")
    evaluate.add_argument(
        "agent",
        metavar="AGENT",
        help="an agent a world ships (foil worlds lists them), an agent file a world loads (a checkpoint, a "
        "TorchScript or Stable-Baselines3 file) or module:attribute (each world's page in docs/)",
    )
    evaluate.add_argument("--episodes", type=int, default=500, help="test episodes (default 500)")
    evaluate.add_argument("--seed", type=int, default=0, help="seed of the test episodes")
    evaluate.add_argument(
        "--time-limit",
        type=float,
        metavar="SECONDS",
        help="seconds an episode may last, in a world with such a setting (default: the world's own; docs/agents.md)",
    )
    evaluate.add_argument(
        "--world",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a world setting over the one the agent brings (each world's page in docs/ lists its settings)",
    )
    evaluate.add_argument(
        "--scenario",
        metavar="NAME|FILE",
        help="the world to evaluate in: a shipped scenario (foil worlds lists them) or a scenario or "
        "distribution file (episodes are seeded by --seed; default: the agent's own test episodes)",
    )
    evaluate.add_argument("--json", action="store_true", help="print one JSON object")
    _jobs_argument(evaluate, "episodes")
    evaluate.set_defaults(handler=_eval)

    add_server_commands(sub)

    render = sub.add_parser("render", help="render a summary.json as an H.264 clip with a poster and contact sheet")
    render.add_argument("summary", metavar="SUMMARY.json", help="a summary written by foil search")
    render.add_argument(
        "--out", required=True, help="the clip to write (.mp4); NAME.poster.png and NAME.sheet.png go next to it"
    )
    render.add_argument("--speed", type=float, default=1.0, help="simulated seconds per second of video (default 1)")
    render.add_argument("--fps", type=int, default=24, help="frames per second, at least 20 (default 24)")
    render.add_argument("--width", type=int, help="width in px (default 720, or 960 side by side)")
    render.add_argument("--crf", type=int, default=23, help="H.264 constant rate factor (default 23)")
    render.add_argument("--numbers", help="the number shown for each summary agent, e.g. 2,1 (default 1,2)")
    render.set_defaults(handler=_render)

    bundle = sub.add_parser("bundle", help="evaluate, search, render and write manifest.json for a study's clips")
    bundle.add_argument("study", metavar="STUDY.toml", help="study file with a [build] table (see docs/clips.md)")
    bundle.add_argument(
        "--out",
        required=True,
        help="bundle directory; searches already there are reused while their inputs are unchanged",
    )
    bundle.add_argument(
        "--jobs",
        type=int,
        default=None,
        help="evaluations, searches, checks and clips to run at once, each in its own process or Ray task "
        "(default: one per core); the bundle is the same whatever the number",
    )
    _backend_arguments(bundle)
    bundle.add_argument(
        "--plan",
        action="store_true",
        help="print each step's count and, from a few timed steps of the world, the expected wall time at --jobs, "
        "then stop (a build itself says each step's jobs done and the time left as it goes)",
    )
    bundle.add_argument(
        "--pilot",
        action="store_true",
        help="vote each pair of the representative scheme as its search will, and at longer clips where the vote is "
        "weak, and compare each shown pair on a few test episodes; say which will be weak or undecided and what "
        "would decide them, then stop",
    )
    bundle.set_defaults(handler=_bundle)

    search = sub.add_parser("search", help="search the scenarios in which agents differ most; write summaries")
    _search_arguments(search)
    search.add_argument(
        "--agents",
        required=True,
        help="two or more agents, comma-separated: A,B[,C] (more "
        "than two are searched jointly, their pairwise divergences combined)",
    )
    search.add_argument(
        "--scenario",
        required=True,
        help="a shipped scenario's name (foil worlds lists them) or a TOML file, the world found from it and "
        "the agents; for the representative solver a distribution of starting states",
    )
    search.add_argument(
        "--solver",
        default=DEFAULT_SOLVER,
        help="mcts (default), nfirst, random, cem, representative (votes over states drawn from --scenario which "
        "agent looks better; docs/search.md), or the field's summary methods disagreements, highlights and "
        "highlights-div (docs/methods.md)",
    )
    _jobs_argument(search, "representative solver's starting states")
    search.set_defaults(handler=_search)

    search_all = sub.add_parser("search-all", help="search every agent pair on every scenario, in parallel")
    _search_arguments(search_all)
    search_all.add_argument("--agents", required=True, help="agents, comma-separated; every pair is searched")
    search_all.add_argument("--scenarios", required=True, help="scenario names or TOML files, comma-separated")
    search_all.add_argument(
        "--solvers", default=DEFAULT_SOLVER, help=f"solvers, comma-separated (default {DEFAULT_SOLVER})"
    )
    search_all.add_argument("--joint", action="store_true", help="search all agents together, not pair by pair")
    search_all.add_argument("--jobs", type=int, help="parallel searches (default: one per core)")
    _backend_arguments(search_all)
    search_all.set_defaults(handler=_search_all)

    verify = sub.add_parser("verify", help="re-simulate summaries; exit status 1 if any number differs")
    verify.add_argument("summaries", nargs="+", metavar="SUMMARY.json")
    verify.set_defaults(handler=_verify)
    return parser


def _search_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--budget", type=int, default=20_000, help="simulator steps to spend (default 20000)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the search (default 0)")
    parser.add_argument("--top-k", type=int, default=30, help="trajectories to keep (default 30; for nfirst: N)")
    parser.add_argument("--out", required=True, help="output directory: summary-001.json ... and run.json")
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="solver setting, e.g. exploration=10 or mode=receding; a length of time in seconds, e.g. horizon=2.5, "
        "or in steps, e.g. horizon_steps=10 (see docs/search.md)",
    )
    parser.add_argument(
        "--reward",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="reward setting, e.g. norm=squared, alpha=2, horizon=25 (seconds: the searched clip's length; "
        "horizon_steps=100 gives steps)",
    )
    parser.add_argument(
        "--world",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="world setting over the scenario's, e.g. env_action_mode=preferred",
    )
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _backend_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--backend",
        choices=("process", "ray"),
        default="process",
        help="process: this machine (default); ray: a Ray cluster (pip install 'foil[ray]'; docs/search.md)",
    )
    parser.add_argument("--ray-address", help="Ray cluster address (default: start a local Ray instance)")


def _jobs_argument(parser: argparse.ArgumentParser, work: str) -> None:
    parser.add_argument(
        "--jobs",
        type=int,
        help=f"processes that share the {work} in a world without a batched fast path (default: one per core; "
        "the result is the same for any number)",
    )


def missing_offline_modules() -> list[str]:
    return [name for name in OFFLINE_MODULES if find_spec(name) is None]


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "handler", None):
        parser.print_help()
        return 0
    if args.command not in SERVER_COMMANDS and (missing := missing_offline_modules()):
        print(
            f"foil {args.command}: error: this install has the survey server only (no {', '.join(missing)}): "
            "install the offline side with pip install 'foil[search]'",
            file=sys.stderr,
        )
        return 2
    try:
        with warnings.catch_warnings():
            warnings.showwarning = partial(_warn, args.command, warnings.showwarning)
            return int(args.handler(args) or 0)
    except (ValueError, FileNotFoundError) as error:
        print(f"foil {args.command}: error: {error}", file=sys.stderr)
        return 2


def _warn(command: str, otherwise: Callable[..., None], message: Warning | str, category: type, *rest: Any) -> None:
    """A setting's warning as one line of the command's, like its errors; any other warning as Python shows it."""
    from search.core.settings import ShortLength

    if issubclass(category, ShortLength):
        print(f"foil {command}: warning: {message}", file=sys.stderr)
    else:
        otherwise(message, category, *rest)


if __name__ == "__main__":
    sys.exit(main())
