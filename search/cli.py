"""The `foil` command line. Each subcommand imports its machinery only when it runs."""

from __future__ import annotations

import argparse
import sys


def _demo(args: argparse.Namespace) -> int:
    from search.demo import run_demo

    return run_demo(scenario=args.scenario, seed=args.seed)


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
