"""The survey server's commands: `foil serve`, `export`, `report`, `simulate`, `power` and `prereg`, their
arguments and what runs them. The `foil` command (search/cli.py) lists them beside the offline side's commands.
Each imports its machinery only when it runs, so `foil --help` loads neither side."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from app.analysis.exclusions import ExclusionRules

COMMANDS = ("serve", "export", "report", "simulate", "power", "prereg")


def comma_separated(text: str) -> list[str]:
    """The names in a comma-separated option (`--include pilot,bot`), blanks left out."""
    return [name.strip() for name in text.split(",") if name.strip()]


def _serve(args: argparse.Namespace) -> int:
    from app.web.serve import serve

    return serve(bundle=args.bundle, study=args.study, database_url=args.db, host=args.host, port=args.port)


def _exclusion_rules(args: argparse.Namespace) -> ExclusionRules:
    from app.analysis.exclusions import ExclusionRules

    return ExclusionRules(
        min_seconds=args.min_seconds,
        median_fraction=args.median_fraction,
        include_kinds=tuple(comma_separated(args.include)),
    )


def _export(args: argparse.Namespace) -> int:
    from app.analysis.export_csv import run_export

    return run_export(
        database_url=args.db, study=args.study, out=args.out, rules=_exclusion_rules(args), bundle=args.bundle
    )


def _report(args: argparse.Namespace) -> int:
    from app.analysis.report import run_report

    return run_report(
        database_url=args.db,
        study=args.study,
        out=args.out,
        rules=_exclusion_rules(args),
        bundle=args.bundle,
        prereg=args.prereg,
        include_excluded=args.include_excluded,
    )


def _simulate(args: argparse.Namespace) -> int:
    from app.analysis.bots import run_simulate

    return run_simulate(
        url=args.url,
        bundle=args.bundle,
        participants=args.participants,
        noise=args.noise,
        seed=args.seed,
        inattentive=args.inattentive,
        first=args.first,
    )


def _power(args: argparse.Namespace) -> int:
    from app.analysis.power import run_power

    return run_power(
        study_path=args.study,
        pairwise=args.pairwise,
        ranking=args.ranking,
        pilot=args.pilot,
        participant_sd=args.participant_sd,
        clip_sd=args.clip_sd,
        largest=args.max_participants,
        studies=args.studies,
        seed=args.seed,
        bundle=args.bundle,
        shown_right=args.shown_right,
    )


def _prereg(args: argparse.Namespace) -> int:
    from app.analysis.prereg import run_prereg

    return run_prereg(
        study_path=args.study,
        bundle=args.bundle,
        out=args.out,
        participants=args.participants,
        rules=_exclusion_rules(args),
    )


def _add_exclusion_options(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--min-seconds",
        type=float,
        help="exclude completions faster than this (default: a "
        "fraction of the median, see --median-fraction; 0: no time rule)",
    )
    command.add_argument(
        "--median-fraction",
        type=float,
        default=1 / 3,
        help="exclude completions faster than this fraction of the median (default 1/3)",
    )
    command.add_argument(
        "--include",
        default="",
        metavar="KINDS",
        help="participant kinds to analyse beside real ones, comma-separated: pilot, bot "
        "(default: none; pilots and bots are left out)",
    )


def add_commands(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds `serve`, `export`, `report` and `simulate` to the `foil` command's subcommands."""
    serve = commands.add_parser("serve", help="run the survey server for a study bundle (applies database migrations)")
    serve.add_argument("--bundle", required=True, type=Path, help="bundle directory holding manifest.json")
    serve.add_argument("--study", type=Path, help="study TOML file (default: study.toml in the bundle)")
    serve.add_argument("--db", help="database URL (default: FOIL_DATABASE_URL or sqlite:///foil.sqlite3)")
    serve.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    serve.add_argument("--port", type=int, default=8000, help="port (default 8000)")
    serve.set_defaults(handler=_serve)

    for name, handler, what in (
        ("export", _export, "long.csv, wide.csv, participants.csv and the codebook"),
        ("report", _report, "report.html with Table 1, the rating figures and tests"),
    ):
        command = commands.add_parser(name, help=f"the survey's answers as {what}")
        command.add_argument("--db", required=True, help="the survey's database URL, e.g. sqlite:///foil.sqlite3")
        command.add_argument(
            "--study",
            help="the id of a study whose file the server stored in the database (default: the only one "
            "stored), or a study file: compared with the stored one, and read only where none is stored",
        )
        command.add_argument("--out", required=True, help="output directory")
        _add_exclusion_options(command)
        command.add_argument(
            "--bundle",
            default=os.environ.get("FOIL_BUNDLE_DIR"),
            help="the bundle the study was served from (default FOIL_BUNDLE_DIR, else the one the server recorded "
            "in the database): its world's words name the agents"
            + ("; each clip's accuracy is shown beside its audit" if name == "report" else ""),
        )
        if name == "report":
            command.add_argument(
                "--prereg",
                help="prereg.json from foil prereg: the report says whether the data match it, listing every deviation",
            )
            command.add_argument(
                "--include-excluded",
                action="store_true",
                help="analyse every participant, whichever exclusion rule leaves them out (a quick look at a pilot, "
                "or at bots that answer sooner than a clip plays); the report says so at its top",
            )
        command.set_defaults(handler=handler)

    simulate = commands.add_parser("simulate", help="bot participants take the study through a running server")
    simulate.add_argument("--url", required=True, help="the server's address, e.g. http://127.0.0.1:8000")
    simulate.add_argument("--participants", type=int, required=True, help="how many bots")
    simulate.add_argument(
        "--bundle",
        help="the bundle the server serves (default FOIL_BUNDLE_DIR): the bots read "
        "what each clip shows from its summary.json",
    )
    simulate.add_argument(
        "--noise", type=float, default=0.5, help="perception noise (default 0.5; see docs/analysis.md)"
    )
    simulate.add_argument(
        "--inattentive",
        type=float,
        default=0.0,
        help="share of bots that answer attention checks at random (default 0)",
    )
    simulate.add_argument("--seed", type=int, default=0, help="seed of the bots (default 0); bot k is bot-SEED-k")
    simulate.add_argument("--first", type=int, default=0, help="number of the first bot (default 0)")
    simulate.set_defaults(handler=_simulate)

    power = commands.add_parser("power", help="participants a study needs: power by simulating its design")
    power.add_argument("study", help="the study file")
    power.add_argument("--pairwise", help="expected pairwise accuracy per scheme, e.g. adaptive=0.85,nfirst=0.7")
    power.add_argument("--ranking", help="expected ranking accuracy per scheme, e.g. adaptive=0.5,nfirst=0.3")
    power.add_argument("--pilot", help="a pilot's database URL: the accuracies the report's model estimates from it")
    power.add_argument(
        "--bundle", help="the study's bundle: pairwise accuracies expected from its audit, undecided pairs and votes"
    )
    power.add_argument(
        "--shown-right",
        type=float,
        default=0.85,
        help="with --bundle: share of right answers to a clip that visibly shows the better agent (default 0.85)",
    )
    power.add_argument("--participant-sd", type=float, default=1.0, help="participants' SD in log odds (default 1)")
    power.add_argument("--clip-sd", type=float, default=0.5, help="clips' SD in log odds (default 0.5)")
    power.add_argument("--max-participants", type=int, default=120, help="largest N tried (default 120)")
    power.add_argument("--studies", type=int, default=100, help="simulated studies per N (default 100)")
    power.add_argument("--seed", type=int, default=0, help="seed of the simulation (default 0)")
    power.set_defaults(handler=_power)

    prereg = commands.add_parser("prereg", help="the preregistration: hypotheses, design, exclusions, model, N")
    prereg.add_argument("study", help="the study file")
    prereg.add_argument("--bundle", required=True, help="the study's bundle (its manifest.json is hashed)")
    prereg.add_argument("--participants", type=int, required=True, help="planned participants (see foil power)")
    prereg.add_argument("--out", required=True, help="output directory for prereg.md and prereg.json")
    _add_exclusion_options(prereg)
    prereg.set_defaults(handler=_prereg)
