"""Pairs of reels (HIGHLIGHTS: each robot on its own, in moments of its own runs): the manifest's contract, the
bundle check, the page, the server's viewing check over both reels and the export, on the real app with a bundle
whose pairwise part shows reels of 1-second real H.264 clips."""

from __future__ import annotations

import csv
import json
import random
import re
import shutil
import time
from datetime import UTC, datetime
from pathlib import Path

import pytest
from pydantic import ValidationError

from app.analysis.export_csv import export_study
from app.formats import MANIFEST_FORMAT, Manifest, ManifestClip, manifest_json
from app.store.database import as_utc
from app.store.models import Participant, Response
from app.survey.assignment import conditions
from app.survey.bundle import BundleError, check_study_against_bundle, load_bundle
from app.survey.kinds import pilot_token
from app.survey.plan import build_plan
from app.survey.study import parse_study
from tests.support.analysis import EXAMPLE, SCENARIOS, SCHEMES, add_reels
from tests.support.survey import (
    AGENT_RANK,
    SECRET_NAMES,
    FormReader,
    answer_for,
    finish,
    start,
    stored,
    study_text,
    watched_reels,
    write_bundle,
)

ANONYMOUS = {"platform": '"none"', "assignment": '"balanced"'}
REEL = {"file": "reels/a.mp4", "sha256": "ab" * 32, "summaries": ["summaries/a-1.json"]}
COUPLED = {"id": "c", "scheme": "s", "scenario": "x", "agents": ["lo", "hi"], "labels": ["Robot 1", "Robot 2"]}


@pytest.fixture(scope="module")
def bundle_dir(tmp_path_factory, clip_files) -> Path:
    """The survey tests' bundle with a pair of reels (each a 1-second clip) for every pairwise screen."""
    root = write_bundle(
        tmp_path_factory.mktemp("reels-bundle"),
        clip_files,
        schemes=SCHEMES,
        scenarios=SCENARIOS,
        agents=AGENT_RANK,
        example=EXAMPLE,
    )
    return add_reels(root, clip_files[0])


def reels_of(**changes) -> dict:
    return COUPLED | {"better": "hi", "reels": [REEL | {"agent": "lo"}, REEL | {"agent": "hi"}]} | changes


def test_a_clip_is_coupled_or_one_reel_per_agent_in_their_order():
    clip = ManifestClip.model_validate(reels_of())
    assert (clip.file, clip.sha256, clip.summary) == ("", "", "") and [r.agent for r in clip.reels] == ["lo", "hi"]
    assert ManifestClip.model_validate(COUPLED | {"better": "hi", "file": "f.mp4", "sha256": "ab"}).reels == []
    for bad, message in [
        (reels_of(reels=[REEL | {"agent": "hi"}, REEL | {"agent": "lo"}]), "one per agent in the order of agents"),
        (reels_of(reels=[REEL | {"agent": "lo"}]), "one per agent"),
        (reels_of(file="f.mp4"), "a clip of reels has no file, sha256 or summary of its own"),
        (reels_of(summary="summaries/s.json"), "a clip of reels has no file, sha256 or summary"),
        (COUPLED | {"better": "hi"}, "a clip needs its file and sha256, or one reel per agent"),
        (reels_of(reels=[REEL | {"agent": "lo", "file": ""}, REEL | {"agent": "hi"}]), "reels.0.file"),
        (reels_of(spent={"sim_steps": 10}), "spent.clip_seconds"),
        (reels_of(spent={"sim_steps": -1, "clip_seconds": 2.0}), "spent.sim_steps"),
    ]:
        with pytest.raises(ValidationError, match=message):
            ManifestClip.model_validate(bad)


# A manifest as `foil bundle` wrote them before clips had reels or a cost: it must read and write byte for byte.
OLD_MANIFEST = {
    "format": MANIFEST_FORMAT,
    "label_seed": 3,
    "clips": [
        {
            "id": "a",
            "file": "clips/a.mp4",
            "sha256": "ab" * 32,
            "scheme": "s",
            "scenario": "sc",
            "agents": ["lo", "hi"],
            "labels": ["Robot 1", "Robot 2"],
            "better": "hi",
            "summary": "summaries/a.json",
            "audit": {"shows": "better", "why": "Robot 2 reached the goal after 9.0 seconds."},
            "poster": "clips/a.png",
            "sheet": "clips/a.sheet.png",
            "parts": ["pairwise"],
            "solver": "mcts",
            "reward": 1.5,
            "outcomes": [{"event": "success", "time": 9.0}],
        }
    ],
    "agents": {"lo": {"episodes": 10}},
    "sources": {},
    "files": {"clips/a.mp4": "ab" * 32},
    "representativeness": [],
}


def test_a_manifest_without_reels_or_cost_reads_and_writes_byte_for_byte():
    text = json.dumps(OLD_MANIFEST, indent=1) + "\n"
    assert manifest_json(Manifest.model_validate_json(text)) == text
    spent = {"sim_steps": 20000, "clip_seconds": 12.5}
    with_cost = json.loads(text)
    with_cost["clips"][0]["spent"] = spent
    written = manifest_json(Manifest.model_validate(with_cost))
    assert json.loads(written)["clips"][0]["spent"] == spent and '"reels"' not in written


def test_the_bundle_check_reads_every_reels_file(bundle_dir, tmp_path):
    bundle = load_bundle(bundle_dir)
    clip = next(clip for clip in bundle.clips.values() if clip.reels)
    assert [bundle.paths[reel.sha256] for reel in clip.reels] == [(bundle_dir / r.file).resolve() for r in clip.reels]
    copy = shutil.copytree(bundle_dir, tmp_path / "bundle")
    (copy / clip.reels[1].file).write_bytes(b"not the reel")
    with pytest.raises(BundleError, match=re.escape(f"{clip.reels[1].file!r} does not match its sha256")):
        load_bundle(copy)


def test_a_ranking_round_of_reels_watches_each_pair_and_lists_every_reel(bundle_dir, tmp_path):
    study = parse_study(study_text())
    copy = shutil.copytree(bundle_dir, tmp_path / "bundle")
    manifest = json.loads((copy / "manifest.json").read_text())
    first_reel = {}  # a HIGHLIGHTS reel is one robot's: the same file whichever robot it is paired with
    for clip in manifest["clips"]:
        if clip["id"].endswith("-reels"):
            clip["parts"] = ["pairwise", "ranking"]  # the ranking part shows reels too
            for reel in clip["reels"]:
                reel.update(first_reel.setdefault((clip["scheme"], clip["scenario"], reel["agent"]), dict(reel)))
        elif clip["parts"] == ["ranking"]:
            clip["parts"] = ["pairwise"]
    (copy / "manifest.json").write_text(json.dumps(manifest))
    bundle = load_bundle(copy)
    check_study_against_bundle(study, bundle)
    reels = {reel.sha256.lower(): clip for clip in bundle.clips.values() for reel in clip.reels}
    rng = random.Random(0)
    rounds = [
        screen
        for condition in conditions(study)
        for screen in build_plan(study, bundle, condition, rng)
        if screen.kind == "ranking"
    ]
    assert rounds and all(set(ranking.media_list) <= set(reels) for ranking in rounds)
    for ranking in rounds:
        assert len(ranking.media_list) == len(ranking.robots)  # each robot's reel once, however often paired
        page = ranking.page(study, bundle)
        assert page["round_reels"]
        for clip in page["round_clips"]:  # one line a moment, each saying which
            moments = len(clip["outcomes"])
            assert moments > 1 and [line.split(":")[0] for line in clip["outcomes"]] == [
                f"Moment {i} of {moments}" for i in range(1, moments + 1)
            ]


def to_reels(client, query: str = "") -> str:
    page = start(client, query)
    response = client.post("/study", data=answer_for(page))  # the instructions
    assert response.status_code == 200 and FormReader(response.text).reels == 2
    return response.text


def test_a_reels_screen_shows_each_robots_reel_with_its_label_and_serves_them(make_client, bundle_dir):
    client = make_client(ANONYMOUS)
    page = to_reels(client)
    plan = stored(client, Participant)[0].plan
    screen = plan[1]
    assert "media" not in screen and [reel["clip_ms"] for reel in screen["reels"]] == [1000, 1000]
    labels = [robot["label"] for robot in screen["robots"]]
    assert sorted(reel["label"] for reel in screen["reels"]) == sorted(labels)
    assert "Each robot is shown on its own, in moments from its own runs through a crowd." in page
    for k, reel in enumerate(screen["reels"]):
        assert f'data-reel="{k}"' in page and f"/clips/{reel['media']}.mp4" in page
        assert f"Clip of one robot on its own in a crowd: {reel['label']}" in page
        served = client.get(f"/clips/{reel['media']}.mp4")
        bundle = load_bundle(bundle_dir)
        assert served.status_code == 200 and served.content == bundle.paths[reel["media"]].read_bytes()
    assert not any(name in page for name in SECRET_NAMES.values())  # no agent or scheme behind the reels


def test_a_reels_screen_is_answered_only_after_every_reel_ended_and_both_reels_time(make_client):
    client = make_client(ANONYMOUS)
    page = to_reels(client)
    one_reel = client.post("/study", data=answer_for(page) | {"video_events": watched_reels([0])})
    assert one_reel.status_code == 422 and "Please watch each clip to the end" in one_reel.text
    # Both reels ended, by the page's record, at once: longer than either reel, shorter than the two together.
    too_soon = client.post("/study", data=answer_for(page))
    assert too_soon.status_code == 422 and "The clips play for 2 seconds together" in too_soon.text
    assert FormReader(too_soon.text).disabled_answers and [r.step for r in stored(client, Response)] == [0]

    shown_at = as_utc(stored(client, Participant)[0].step_started_at)
    time.sleep(max(0.0, 1.05 - (datetime.now(UTC) - shown_at).total_seconds()))  # both reels less the tolerance
    accepted = client.post("/study", data=answer_for(page))
    assert accepted.status_code == 200 and FormReader(accepted.text).hidden["step"] == "2"
    saved = stored(client, Response)[1]
    assert {(e["type"], e.get("reel")) for e in saved.video_events} >= {("ended", 0), ("ended", 1)}


def test_the_export_has_a_row_per_answer_about_a_reels_clip(make_client, tmp_path):
    client = make_client(ANONYMOUS)
    token = pilot_token(client.app.state.context.db, "paper")
    finish(client, to_reels(client, f"?pilot={token}"))
    export_study(client.app.state.context.db, client.app.state.context.study, tmp_path / "export")
    rows = list(csv.DictReader((tmp_path / "export" / "long.csv").open(encoding="utf-8")))
    reels = [row for row in rows if row["clip"].endswith("-reels")]
    assert {row["screen"] for row in reels} == {"pairwise"} and len({row["clip"] for row in reels}) == 6
    assert {row["clip_ms"] for row in reels} == {"2000"} and {row["plays"] for row in reels} == {"2"}
    chosen = [row for row in reels if row["question"] == "better"]
    assert len(chosen) == 6
    assert all(row["truth"] == max(row["agents"].split(";"), key=AGENT_RANK.index) for row in chosen)
    assert all(row["correct"] == str(int(row["answer_agent"] == row["truth"])) for row in chosen)
    coupled = [row for row in rows if row["screen"] == "watch"]
    assert coupled and {row["clip_ms"] for row in coupled} == {"1000"}  # the ranking part's clips of both robots


def test_reels_are_refused_where_one_video_is_shown(bundle_dir, tmp_path):
    study = parse_study(study_text())
    copy = shutil.copytree(bundle_dir, tmp_path / "bundle")
    manifest = json.loads((copy / "manifest.json").read_text())
    example = next(clip for clip in manifest["clips"] if clip["scenario"] == EXAMPLE[1])
    reels = next(clip for clip in manifest["clips"] if clip.get("reels"))
    ordered = [reel | {"agent": agent} for reel, agent in zip(reels["reels"], example["agents"], strict=True)]
    manifest["clips"].remove(example)
    manifest["clips"].append(
        {key: example[key] for key in ("id", "scheme", "scenario", "agents", "labels", "better", "parts")}
        | {"reels": ordered}
    )
    (copy / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(BundleError, match=r"example.* would show clips of reels"):
        check_study_against_bundle(study, load_bundle(copy))
