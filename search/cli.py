"""The `foil` command line. Each subcommand imports its machinery only when it runs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _demo(args: argparse.Namespace) -> int:
    from search.demo import run_demo

    return run_demo(scenario=args.scenario, seed=args.seed)


def _train(args: argparse.Namespace) -> int:
    from search.train import load_train_config, train

    last = train(load_train_config(args.config), args.out)
    print(f"last checkpoint: {last}")
    return 0


def _eval(args: argparse.Namespace) -> int:
    from search.evaluate import run_eval

    return run_eval(args.agent, episodes=args.episodes, seed=args.seed, as_json=args.json)


def _serve(args: argparse.Namespace) -> int:
    from app.serve import serve

    return serve(bundle=args.bundle, study=args.study, database_url=args.db, host=args.host, port=args.port)


def _exclusion_rules(args: argparse.Namespace):
    from app.exclusions import ExclusionRules

    return ExclusionRules(min_seconds=args.min_seconds, median_fraction=args.median_fraction)


def _export(args: argparse.Namespace) -> int:
    from app.export_csv import run_export

    return run_export(database_url=args.db, study=args.study, out=args.out, rules=_exclusion_rules(args))


def _report(args: argparse.Namespace) -> int:
    from app.report import run_report

    return run_report(database_url=args.db, study=args.study, out=args.out, rules=_exclusion_rules(args))


def _simulate(args: argparse.Namespace) -> int:
    from app.bots import run_simulate

    return run_simulate(url=args.url, bundle=args.bundle, participants=args.participants, noise=args.noise,
                        seed=args.seed, inattentive=args.inattentive, first=args.first)


def _render(args: argparse.Namespace) -> int:
    from search.render import RenderOptions, render_file

    options = RenderOptions(fps=args.fps, speed=args.speed, width=args.width, crf=args.crf)
    numbers = [int(n) for n in args.numbers.split(",")] if args.numbers else None
    result = render_file(args.summary, args.out, numbers=numbers, options=options)
    print(f"{result.clip}: {result.frames} frames, {result.seconds:.1f} s, {result.width}x{result.height}, "
          f"rendered in {result.render_s:.2f} s; poster {result.poster.name}, contact sheet {result.sheet.name}")
    return 0


def _bundle(args: argparse.Namespace) -> int:
    from search.bundle import build_bundle

    build_bundle(args.study, args.out)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="foil",
        description="Contrasting behaviour summaries of robot policies, and the user study that tests them.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    demo = sub.add_parser("demo", help="run the demo: two scripted robots through a shipped scenario")
    demo.add_argument("--scenario", default="paper-bl-tr", help="shipped scenario name or TOML file")
    demo.add_argument("--seed", type=int, default=0, help="seed of the environment actions")
    demo.set_defaults(handler=_demo)

    train = sub.add_parser("train", help="train a DS-RNN robot with PPO (resumes a run found in --out)")
    train.add_argument("--config", required=True, help="TOML file of training settings (see docs/agents.md)")
    train.add_argument("--out", required=True, help="run directory: progress.csv and checkpoints/")
    train.set_defaults(handler=_train)

    evaluate = sub.add_parser("eval", help="success, collision and timeout rates and mean reward of an agent")
    evaluate.add_argument("agent", metavar="AGENT", help="lo, med, hi, a scripted policy, a checkpoint or "
                          "TorchScript file, or module:attribute")
    evaluate.add_argument("--episodes", type=int, default=500, help="test episodes (default 500)")
    evaluate.add_argument("--seed", type=int, default=0, help="seed of the test episodes")
    evaluate.add_argument("--json", action="store_true", help="print one JSON object")
    evaluate.set_defaults(handler=_eval)

    serve = sub.add_parser("serve", help="run the survey server for a study bundle (applies database migrations)")
    serve.add_argument("--bundle", required=True, type=Path, help="bundle directory holding manifest.json")
    serve.add_argument("--study", type=Path, help="study TOML file (default: study.toml in the bundle)")
    serve.add_argument("--db", help="database URL (default: FOIL_DATABASE_URL or sqlite:///foil.sqlite3)")
    serve.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    serve.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    serve.set_defaults(handler=_serve)

    for name, handler, what in (("export", _export, "long.csv, wide.csv, participants.csv and the codebook"),
                                ("report", _report, "report.html with Table 1, the rating figures and tests")):
        command = sub.add_parser(name, help=f"the survey's answers as {what}")
        command.add_argument("--db", required=True, help="the survey's database URL, e.g. sqlite:///foil.sqlite3")
        command.add_argument("--study", help="the study file the survey was served with, or the id of a study "
                             "whose file the server stored in the database (default: the only one stored)")
        command.add_argument("--out", required=True, help="output directory")
        command.add_argument("--min-seconds", type=float, help="exclude completions faster than this (default: a "
                             "fraction of the median, see --median-fraction; 0: no time rule)")
        command.add_argument("--median-fraction", type=float, default=1 / 3,
                             help="exclude completions faster than this fraction of the median (default 1/3)")
        command.set_defaults(handler=handler)

    simulate = sub.add_parser("simulate", help="bot participants take the study through a running server")
    simulate.add_argument("--url", required=True, help="the server's address, e.g. http://127.0.0.1:8000")
    simulate.add_argument("--participants", type=int, required=True, help="how many bots")
    simulate.add_argument("--bundle", help="the bundle the server serves (default FOIL_BUNDLE_DIR): the bots read "
                          "what each clip shows from its summary.json")
    simulate.add_argument("--noise", type=float, default=0.5,
                          help="perception noise (default 0.5; see docs/analysis.md)")
    simulate.add_argument("--inattentive", type=float, default=0.0,
                          help="share of bots that answer attention checks at random (default 0)")
    simulate.add_argument("--seed", type=int, default=0, help="seed of the bots (default 0); bot k is bot-SEED-k")
    simulate.add_argument("--first", type=int, default=0, help="number of the first bot (default 0)")
    simulate.set_defaults(handler=_simulate)

    render = sub.add_parser("render", help="render a summary.json as an H.264 clip with a poster and contact sheet")
    render.add_argument("summary", metavar="SUMMARY.json", help="a summary written by foil search")
    render.add_argument("--out", required=True, help="the clip to write (.mp4); NAME.poster.png and "
                        "NAME.sheet.png go next to it")
    render.add_argument("--speed", type=float, default=1.0, help="simulated seconds per second of video (default 1)")
    render.add_argument("--fps", type=int, default=24, help="frames per second, at least 20 (default 24)")
    render.add_argument("--width", type=int, help="width in px (default 720, or 960 side by side)")
    render.add_argument("--crf", type=int, default=23, help="H.264 constant rate factor (default 23)")
    render.add_argument("--numbers", help="robot number shown for each summary agent, e.g. 2,1 (default 1,2)")
    render.set_defaults(handler=_render)

    bundle = sub.add_parser("bundle", help="evaluate, search, render and write manifest.json for a study's clips")
    bundle.add_argument("study", metavar="STUDY.toml", help="study file with a [build] table (see docs/clips.md)")
    bundle.add_argument("--out", required=True, help="bundle directory; searches already there are reused while "
                        "their inputs are unchanged")
    bundle.set_defaults(handler=_bundle)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "handler", None):
        parser.print_help()
        return 0
    try:
        return int(args.handler(args) or 0)
    except (ValueError, FileNotFoundError) as error:
        print(f"foil {args.command}: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
