"""`foil prereg` and `foil report --prereg` cannot be fooled: the study text the server stored is the authority,
every server start is kept, the hashes are of the files' bytes (as `sha256sum` prints them), and the versions of
Foil and of the report's model are fixed. Real SQLite files, started through the server's own start-up."""

from __future__ import annotations

import hashlib
import json
from importlib.metadata import version

import pytest

from app.analysis.model import MODEL_VERSION
from tests.app.analysis.test_report import known_answers, known_db  # noqa: F401  (the fixture)

EDITED = "\n# an edit made while the study was collecting\n"


def sha256sum(path) -> str:
    return "sha256:" + hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def served(known_db, paper_study, bundle_dir, tmp_path, monkeypatch):  # noqa: F811
    """The four analysed participants' database, the study file, a preregistration of it (4 participants) and a
    function that starts the server on a study file, as `foil serve` does."""
    from app.web.main import create_app
    from app.web.settings import ServerSettings
    from search.cli import main

    monkeypatch.delenv("FOIL_BUNDLE_DIR", raising=False)
    db, _ = known_db
    path, _ = paper_study
    prereg = tmp_path / "prereg"
    assert main(["prereg", str(path), "--bundle", str(bundle_dir), "--participants", "4", "--out", str(prereg)]) == 0

    def start(study_file=path):
        settings = ServerSettings(bundle_dir=bundle_dir, study_file=study_file, database_url=db.url)
        create_app(settings).state.context.db.dispose()

    return db, path, prereg / "prereg.json", start


def report(db, tmp_path, capsys, *options: str) -> tuple[str, str]:
    """`foil report` on the database: what it printed and the report's HTML."""
    from search.cli import main

    capsys.readouterr()
    out = tmp_path / f"report-{len(list(tmp_path.glob('report-*')))}"
    assert main(["report", "--db", db.url, "--out", str(out), *options]) == 0
    printed = capsys.readouterr()
    return printed.out + printed.err, (out / "report.html").read_text()


def test_a_study_file_given_to_the_report_never_replaces_the_one_the_server_stored(served, tmp_path, capsys):
    db, path, prereg, start = served
    original = tmp_path / "original.toml"
    original.write_bytes(path.read_bytes())
    path.write_text(path.read_text() + EDITED)
    start(path)  # the server served an edited file
    printed, html = report(db, tmp_path, capsys, "--study", str(original), "--prereg", str(prereg))
    assert "The data match the preregistration" not in html
    assert "2 deviations from the preregistration" in printed
    assert f"the study file differs from the preregistered one ({sha256sum(path)}" in printed
    assert f"the study file {original} ({sha256sum(original)}) differs from the one the server stored" in printed

    printed, _ = report(db, tmp_path, capsys, "--study", str(original))
    assert f"warning: the study file {original} ({sha256sum(original)}) differs from the one" in printed
    assert "the stored one is analysed" in printed


def test_an_edit_served_during_collection_and_reverted_later_is_a_deviation(served, tmp_path, capsys):
    db, path, prereg, start = served
    original = path.read_text()
    start()
    path.write_text(original + EDITED)
    edited = sha256sum(path)
    start()
    path.write_text(original)
    start()
    printed, html = report(db, tmp_path, capsys, "--prereg", str(prereg))
    assert "The data match the preregistration" not in html
    assert "1 deviation from the preregistration" in printed
    assert "the server was started 3 times; the 2nd start (" in printed
    assert f") served a study file that differs from the preregistered one ({edited}), later reverted" in printed


def test_hashes_are_of_the_files_bytes_as_sha256sum_prints_them(served, paper_study, bundle_dir, tmp_path, capsys):
    from search.cli import main

    db, path, _, start = served
    path.write_bytes(path.read_bytes().replace(b"\n", b"\r\n"))  # saved on Windows
    prereg = tmp_path / "crlf"
    assert main(["prereg", str(path), "--bundle", str(bundle_dir), "--participants", "4", "--out", str(prereg)]) == 0
    fixed = json.loads((prereg / "prereg.json").read_text())
    assert fixed["study_file"] == sha256sum(path)
    assert fixed["bundle_manifest"] == sha256sum(bundle_dir / "manifest.json")
    from app.analysis.source import study_starts

    start()
    [started] = study_starts(db, paper_study[1].study.id)
    assert (started["study_file"], started["bundle_manifest"]) == (fixed["study_file"], fixed["bundle_manifest"])
    printed, html = report(db, tmp_path, capsys, "--prereg", str(prereg))
    assert "The data match the preregistration" in html and "deviations" not in printed


def test_the_versions_of_foil_and_of_the_model_are_preregistered(served, tmp_path, capsys):
    db, _, prereg, start = served
    start()
    fixed = json.loads(prereg.read_text())
    assert (fixed["version"], fixed["foil"], fixed["model_version"]) == (2, version("foil"), MODEL_VERSION)
    assert f"Foil {version('foil')}" in (prereg.parent / "prereg.md").read_text()

    prereg.write_text(json.dumps({**fixed, "foil": "0.0.1", "model_version": MODEL_VERSION - 1}))
    printed, _ = report(db, tmp_path, capsys, "--prereg", str(prereg))
    assert "2 deviations from the preregistration" in printed
    assert f"Foil is version {version('foil')}, the preregistration fixed version 0.0.1" in printed
    assert f"the report's model is version {MODEL_VERSION}, the preregistration fixed version {MODEL_VERSION - 1}" in (
        printed
    )

    older = {key: value for key, value in fixed.items() if key not in ("foil", "model_version")}
    prereg.write_text(json.dumps({**older, "version": 1}))  # written before the versions were recorded
    printed, _ = report(db, tmp_path, capsys, "--prereg", str(prereg))
    assert "2 deviations from the preregistration" in printed
    assert (
        f"does not record the version of Foil, so a change of it cannot be ruled out (this report: {version('foil')})"
        in (printed)
    )
    assert "does not record the version of the report's model" in printed


def test_a_primary_test_the_design_cannot_run_is_not_preregistered(tmp_path):
    """The demo's ranking part has one ranked set of the representative scheme: the report can never test its
    schemes, so the preregistration says so, in the report's words, instead of fixing a test that cannot run."""
    from pathlib import Path

    from app.analysis.exclusions import ExclusionRules
    from app.analysis.prereg import markdown, plan
    from app.survey.study import parse_study

    raw = (Path(__file__).parents[3] / "studies" / "demo.toml").read_bytes()
    manifest = tmp_path / "manifest.json"
    manifest.write_text("{}")
    fixed = plan(raw, parse_study(raw.decode("utf-8")), manifest, 40, ExclusionRules())
    assert list(fixed["untestable"]) == ["ranking"]
    assert fixed["untestable"]["ranking"].startswith("in a simulated study of 40 participants, only ")
    assert "representative left out (fewer than two clips)" in fixed["untestable"]["ranking"]
    pairwise, ranking = fixed["hypotheses"]
    assert "(the primary test, two-sided" in pairwise
    assert ranking.startswith("ranking: no test that the schemes differ is preregistered, as this design cannot")
    assert ranking in markdown(fixed)


def test_one_participant_analysed_is_said_in_the_singular(tmp_path):
    from app.analysis.exclusions import ExclusionRules
    from app.analysis.prereg import deviations, plan
    from app.survey.study import parse_study
    from tests.support.survey import study_text

    text = study_text()
    manifest = tmp_path / "manifest.json"
    manifest.write_text("{}")
    fixed = plan(text.encode("utf-8"), parse_study(text), manifest, 3, ExclusionRules())
    found = deviations(fixed, text, manifest, 1, ExclusionRules())
    assert "1 participant analysed, fewer than the 3 planned" in found
