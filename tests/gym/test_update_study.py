"""The shipped study of updates (studies/cartpole-updates.toml), end to end on a tiny budget: snapshots of one
CartPole training run bundled, served, answered three ways by bots, exported and reported with the accuracy on
decided updates, the "no difference" rate on equal pairs and the bias to call an update better; `foil power` and
`foil prereg` take its design."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

from app.analysis.bots import simulate
from app.analysis.source import analysis_database
from app.survey.kinds import pilot_token
from search.cli import main
from tests.app.analysis.test_simulate import serve

ROOT = Path(__file__).parents[2]
STUDY = ROOT / "studies" / "cartpole-updates.toml"


def small(text: str) -> str:
    """The study with budgets and clips for a test."""
    for old, new in (
        ("budget = 20_000", "budget = 1_500"),
        ("budget = 4_000", "budget = 400"),
        ("episodes = 20", "episodes = 4"),
        ("horizon = 4.0", "horizon = 2.0"),
    ):
        assert old in text
        text = text.replace(old, new)
    return text


def test_a_study_of_updates_is_built_served_answered_three_ways_and_reported(tmp_path, monkeypatch, capsys):
    folder = tmp_path / "cartpole"
    shutil.copytree(ROOT / "docs" / "examples" / "cartpole", folder, ignore=shutil.ignore_patterns("__pycache__"))
    text = small(STUDY.read_text())
    (folder / "updates.toml").write_text(text)
    monkeypatch.chdir(folder)
    assert main(["bundle", "updates.toml", "--out", "bundle"]) == 0
    manifest = json.loads((folder / "bundle" / "manifest.json").read_text())
    undecided = [pair["agents"] for pair in manifest["close_pairs"] if not pair["decided"]]
    assert undecided == [["cartpole_run:snapshot_2", "cartpole_run:snapshot_3"]]  # the control: one controller

    served = serve(tmp_path, folder / "bundle", text)
    url, db_url, _ = next(served)
    try:
        db = analysis_database(db_url)
        token = pilot_token(db, "cartpole-updates")
        db.dispose()
        runs = simulate(url, folder / "bundle", 6, noise=0.3, seed=3, pilot_token=token)
    finally:
        next(served, None)
    assert all(run.completed for run in runs)
    verdicts = [a["value"] for run in runs for a in run.answers if a["question"] == "verdict"]
    assert len(verdicts) == 6 * 6 and "no difference" in verdicts  # the control's clips show one controller twice
    capsys.readouterr()

    args = ["--db", db_url, "--include", "bot", "--min-seconds", "600"]
    assert main(["export", *args, "--out", str(tmp_path / "export")]) == 0
    with (tmp_path / "export" / "long.csv").open(encoding="utf-8") as handle:
        rows = [row for row in csv.DictReader(handle) if row["question"] == "verdict"]
    assert {row["update"] for row in rows} == {"better", "worse", "equal"}
    assert {row["later_first"] for row in rows} == {"0", "1"}  # the order of the versions is not fixed
    for row in rows:
        later, called = row["later"], row["called"]
        assert called == {later: "later", "no difference": "no difference"}.get(row["answer_agent"], "earlier")
        assert row["correct"] == str(int(row["answer_agent"] == row["truth"]))
        assert (row["truth"] == "no difference") == (row["update"] == "equal")
    codebook = (tmp_path / "export" / "codebook.md").read_text()
    assert "`called`" in codebook and "compare" in codebook

    assert main(["report", *args, "--out", str(tmp_path / "report")]) == 0
    reported = capsys.readouterr().out
    for measure in (
        "right on decided updates",
        "no difference on equal pairs",
        "later called better on equal and worse updates",
    ):
        for scheme in ("nfirst", "representative"):
            lines = [line for line in reported.splitlines() if line.startswith(f"{measure}, {scheme}:")]
            assert len(lines) == 1 and ("95% interval" in lines[0] or "not tested" in lines[0]), reported
    with (tmp_path / "report" / "updates.csv").open(encoding="utf-8") as handle:
        table = list(csv.DictReader(handle))
    equal = [row for row in table if row["measure"] == "no difference on equal pairs" and row["scheme"] == "nfirst"]
    assert equal and float(equal[0]["rate"]) > 0
    report = (tmp_path / "report" / "report.html").read_text()
    assert "Updates: is the later version better?" in report

    power = ["power", "updates.toml", "--pairwise", "nfirst=0.7,representative=0.6", "--studies", "10"]
    assert main([*power, "--max-participants", "12"]) == 0
    assert "power, answers" in capsys.readouterr().out
    assert main(["prereg", "updates.toml", "--bundle", "bundle", "--out", "prereg", "--participants", "12"]) == 0
    fixed = json.loads((folder / "prereg" / "prereg.json").read_text())
    assert fixed["design"]["controls"] == [["cartpole_run:snapshot_2", "cartpole_run:snapshot_3"]]
    assert any(h.startswith("updates:") for h in fixed["hypotheses"])
    assert "(0.333)" in fixed["hypotheses"][0] or "cannot run it" in fixed["hypotheses"][0]  # one of three answers
