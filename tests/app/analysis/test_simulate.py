"""foil simulate: bots take the whole paper study through a real server over HTTP, and the report counts exactly
what they answered."""

from __future__ import annotations

import csv
import json
import shutil
import threading
import time
from collections import Counter

import pytest
import uvicorn

from app.analysis.bots import Observer, VisibleClip, simulate
from app.analysis.exclusions import ExclusionRules
from app.analysis.report import ALL, render_report, tally_study
from app.analysis.source import analysis_database
from app.store.database import migrate
from app.survey.study import parse_study
from app.web.main import create_app
from app.web.settings import ServerSettings
from search.cli import main
from tests.support.analysis import MISLEADING, SCHEMES
from tests.support.survey import AGENT_RANK, ATTENTION, SECRET_NAMES, study_text

pytestmark = pytest.mark.slow  # bots take the whole study through a real server


COMPREHENSION = """
[[comprehension]]
text = "What makes a robot good in this study?"
options = ["Reaching its goal first", "Reaching its goal without touching anyone", "Staying far from people"]
expected = "Reaching its goal without touching anyone"
"""


@pytest.fixture
def live_server(tmp_path, bundle_dir):
    """The real app under uvicorn on 127.0.0.1 (a free port) in a thread, with the paper study as shipped
    (MTurk, self-selected condition) plus an attention check; stopped at the end of the test."""
    yield from serve(tmp_path, bundle_dir, study_text() + ATTENTION)


@pytest.fixture
def comprehension_server(tmp_path, bundle_dir):
    """The same with a comprehension question on the instructions page instead of the attention check."""
    yield from serve(tmp_path, bundle_dir, study_text() + COMPREHENSION)


def serve(tmp_path, bundle_dir, text: str):
    study_file = tmp_path / "study.toml"
    study_file.write_text(text)
    url = f"sqlite:///{tmp_path / 'survey.sqlite3'}"
    migrate(url)
    app = create_app(ServerSettings(bundle_dir=bundle_dir, study_file=study_file, database_url=url))
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=0, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    for _ in range(500):
        if server.started:
            break
        time.sleep(0.01)
    port = server.servers[0].sockets[0].getsockname()[1]
    yield f"http://127.0.0.1:{port}", url, study_file
    server.should_exit = True
    thread.join(timeout=10)
    app.state.context.db.dispose()


def test_bots_take_the_study_and_the_report_counts_their_answers(live_server, bundle_dir, tmp_path):
    url, db_url, study_file = live_server
    runs = simulate(url, bundle_dir, 8, noise=0.3, seed=1, inattentive=0.5)
    assert all(run.completed and run.completion_code == "FOIL-PAPER-7Q2K" for run in runs)

    manifest = {clip["sha256"]: clip for clip in json.loads((bundle_dir / "manifest.json").read_text())["clips"]}
    expected: Counter = Counter()
    ratings: Counter = Counter()
    misleading_answers = []
    analysed = 0
    for run in runs:
        answers = {(a["step"], a["question"]): a for a in run.answers}
        if any(q == "attention" and a["value"] != "Agree" for (_, q), a in answers.items()):
            continue  # failed the attention check: the report leaves the bot out
        analysed += 1
        for (_, question), answer in answers.items():
            if question == "better":
                clip = manifest[answer["clip"]]
                agent = clip["agents"][clip["labels"].index(answer["value"])]
                expected[("pairwise", clip["scheme"], agent == clip["better"])] += 1
                if clip["id"] == MISLEADING:
                    misleading_answers.append(agent)
            elif question == "ranking":
                clip = manifest[answer["clips"][0]]
                agent_of = {
                    label: agent
                    for c in answer["clips"]
                    for label, agent in zip(manifest[c]["labels"], manifest[c]["agents"], strict=True)
                }
                order = [agent_of[label] for label in answer["value"]]
                expected[("ranking", clip["scheme"], order == AGENT_RANK[::-1])] += 1
            elif question in ("difficulty", "easy_middle_best"):
                ratings[question] += 1
    assert 0 < analysed < len(runs)  # some bots failed the check, some passed

    db = analysis_database(db_url)
    by_default = tally_study(db, parse_study(study_file.read_text()), ExclusionRules(min_seconds=0))
    assert by_default.exclusions.after == 0 and by_default.exclusions.per_reason["pilot_or_bot"] == 8  # bots out
    data = tally_study(db, parse_study(study_file.read_text()), ExclusionRules(min_seconds=0, include_kinds=("bot",)))
    db.dispose()
    assert data.exclusions.before == 8 and data.exclusions.after == analysed
    assert data.exclusions.per_reason["skipped_viewing"] == 0  # without the pilot token the bots waited
    for task in ("pairwise", "ranking"):
        for scheme in SCHEMES:
            tally = data.tally(task, ALL, scheme)
            assert (tally.correct, tally.incorrect) == (expected[(task, scheme, True)], expected[(task, scheme, False)])
    assert data.tally("pairwise", ALL, SCHEMES[0]).n == 3 * analysed
    assert sum(sum(c.values()) for c in data.ratings["difficulty"].values()) == ratings["difficulty"]
    assert (
        sum(sum(c.values()) for c in data.ratings["easy_middle_best"].values())
        == ratings["easy_middle_best"]
        == 2 * analysed
    )  # one ranking per scheme
    # The misleading clip shows the worst robot doing well; bots judge what they see, not the ground truth.
    assert misleading_answers and set(misleading_answers) == {SECRET_NAMES["lo"]}
    render_report(data, tmp_path / "report")


def test_bots_choose_again_after_a_wrong_comprehension_answer(comprehension_server, bundle_dir):
    """The server refuses a wrong comprehension answer with the same page; a bot, like a person who reads the
    error, answers again with another option instead of giving up."""
    url, _, _ = comprehension_server
    runs = simulate(url, bundle_dir, 4, noise=0.3, seed=3)
    assert all(run.completed for run in runs)


def test_cli_simulate_export_report(live_server, bundle_dir, tmp_path, capsys):
    url, db_url, study_file = live_server
    assert main(["simulate", "--url", url, "--participants", "2", "--bundle", str(bundle_dir), "--seed", "3"]) == 0
    assert "2 of 2 bots completed" in capsys.readouterr().out
    assert main(["export", "--db", db_url, "--study", str(study_file), "--out", str(tmp_path / "export")]) == 0
    assert main(["report", "--db", db_url, "--study", str(study_file), "--out", str(tmp_path / "report")]) == 0
    out = capsys.readouterr().out
    assert "2 participants" in out and (tmp_path / "report" / "report.html").exists()
    assert (tmp_path / "export" / "wide.csv").read_text().count("\n") == 3
    # the bots are left out of the analysis unless asked for
    assert json.loads((tmp_path / "export" / "codebook.json").read_text())["exclusion_rules"]["analysed_kinds"] == [
        "real"
    ]
    assert (
        main(
            [
                "export",
                "--db",
                db_url,
                "--study",
                str(study_file),
                "--out",
                str(tmp_path / "with-bots"),
                "--include",
                "bot",
            ]
        )
        == 0
    )
    with_bots = json.loads((tmp_path / "with-bots" / "codebook.json").read_text())["exclusion_rules"]
    assert with_bots["analysed_kinds"] == ["real", "bot"]
    # the too-fast threshold is the real participants' pace (none here), never the bots' own
    assert with_bots["median_duration_s"] is None and with_bots["too_fast_threshold_s"] is None
    # with the bundle, each clip's accuracy stands beside its audit; a folder without a manifest is refused
    audited = tmp_path / "audited-bundle"
    shutil.copytree(bundle_dir, audited)
    manifest = json.loads((audited / "manifest.json").read_text())
    manifest["clips"][0]["audit"] = {"shows": "worse", "why": "Robot 9 bumped into a person early."}
    (audited / "manifest.json").write_text(json.dumps(manifest))
    assert (
        main(
            [
                "report",
                "--db",
                db_url,
                "--study",
                str(study_file),
                "--out",
                str(tmp_path / "audited"),
                "--include",
                "bot",
                "--bundle",
                str(audited),
            ]
        )
        == 0
    )
    assert "Robot 9 bumped into a person early." in (tmp_path / "audited" / "report.html").read_text()
    first = manifest["clips"][0]  # the audit's labels, each named with its agent
    labels = ", ".join(f"{label} = {agent}" for agent, label in zip(first["agents"], first["labels"], strict=True))
    with (tmp_path / "audited" / "per_clip.csv").open() as handle:
        rows = {row["clip"]: row for row in csv.DictReader(handle)}
    assert rows[first["id"]]["audit_labels"] == labels and " = " in labels
    for bad in (
        ["--include", "robots"],
        ["--bundle", str(tmp_path / "nowhere")],
        ["--min-seconds", "nan"],
        ["--min-seconds", "inf"],
        ["--min-seconds", "-1"],
    ):
        assert main(["report", "--db", db_url, "--study", str(study_file), "--out", str(tmp_path / "x"), *bad]) == 2
    # errors are named, not raised
    assert (
        main(
            [
                "report",
                "--db",
                f"sqlite:///{tmp_path / 'nope.sqlite3'}",
                "--study",
                str(study_file),
                "--out",
                str(tmp_path / "x"),
            ]
        )
        == 2
    )
    assert main(["simulate", "--url", url, "--participants", "1"]) == 2
    assert "--bundle DIR" in capsys.readouterr().err


def test_observer_judges_visible_outcomes():
    observer = Observer(noise=0.0)
    clip = VisibleClip(
        labels=("Robot 1", "Robot 2", "Robot 3"),
        end_s=20.0,
        progress=(0.0, 0.0, 0.5),
        outcomes=(
            {"event": "success", "time": 10.0, "min_other_distance": 1.0},
            {"event": "collision", "time": 3.0},
            {"event": "timeout", "time": 20.0, "min_other_distance": 0.3},
        ),
    )
    scores = clip.scores(observer)
    assert scores == {"Robot 1": 2.5, "Robot 2": -1.0, "Robot 3": pytest.approx(0.5 - 2 * 0.2)}
    assert clip.describe("Robot 2") == "Robot 2 bumped into a person."
    assert "came close to people" in clip.describe("Robot 3")
