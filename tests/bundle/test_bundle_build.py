"""A real bundle build: evaluations, `foil search`, rendering, manifest and gallery, then a rebuild from cache."""

from __future__ import annotations

import json

import pytest

from app.formats import manifest_json, sha256_file
from search.bundle.build import build_bundle
from tests.support.survey import survey_tables

pytestmark = pytest.mark.slow

SMALL_STUDY = (
    survey_tables()
    + """
[build]
seed = 7

[build.eval]
episodes = 4
seed = 0

[build.render]
speed = 6.0
hold_start = 0.2
hold_end = 0.2
event_hold = 0.2

[build.representativeness]
states = 3
pushes = 3

[build.schemes.adaptive]
solver = "mcts"
budget = 300
seed = 1
top_k = 5
select = "contrast"

[build.schemes.nfirst]
solver = "nfirst"
budget = 300
seed = 1

[build.schemes.representative]
solver = "representative"
budget = 600
seed = 3  # its clip shows no difference: a misleading clip to mark
settings = { states = 3, pushes = 3 }

[[build.sets]]
parts = ["pairwise", "ranking"]
schemes = ["adaptive", "nfirst"]
scenarios = ["paper-bl-tr"]
agents = ["goal", "orca"]

[[build.sets]]
parts = ["pairwise"]
schemes = ["representative"]
scenarios = ["training"]
agents = ["goal", "orca"]

[[build.sets]]
parts = ["example"]
schemes = ["nfirst"]
scenarios = ["paper-code"]
pairs = [["goal", "orca"]]
"""
)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    root = tmp_path_factory.mktemp("bundle")
    study = root / "study.toml"
    study.write_text(SMALL_STUDY)
    log = []
    manifest = json.loads(manifest_json(build_bundle(study, root / "out", log=log.append)))
    return root / "out", manifest, log, study


def test_manifest_matches_files_and_checksums(built):
    out, manifest, _, _ = built
    assert manifest == json.loads((out / "manifest.json").read_text())
    assert manifest["format"] == "foil.bundle/1"
    assert len(manifest["clips"]) == 4
    agent_of = {}
    for clip in manifest["clips"]:
        assert sha256_file(out / clip["file"]) == clip["sha256"]
        for label, agent in zip(clip["labels"], clip["agents"], strict=True):
            assert agent_of.setdefault(label, agent) == agent  # no label names two agents in the bundle
        assert clip["better"] in clip["agents"]
        summary = json.loads((out / clip["summary"]).read_text())
        assert summary["format"] == "foil.summary/2"
        assert sorted(a["name"] for a in summary["agents"]) == sorted(clip["agents"])
        for key in ("poster", "sheet"):
            assert (out / clip[key]).is_file()
        assert not any(agent in clip["file"] or agent in clip["id"] for agent in clip["agents"])
    assert set(manifest["agents"]) == {"goal", "orca"}
    assert manifest["agents"]["goal"]["episodes"] == 4
    for name, digest in manifest["files"].items():
        assert sha256_file(out / name) == digest, name
    listed = set(manifest["files"])
    on_disk = {str(p.relative_to(out)) for p in out.rglob("*") if p.is_file() and p.parts[len(out.parts)] != "cache"}
    assert on_disk - {"manifest.json"} == listed
    # two rounds of two, the representative scheme's pair, then the example's two
    assert sorted(agent_of, key=lambda label: int(label.split()[1])) == [f"Robot {n}" for n in range(1, 9)]
    gallery = (out / "index.html").read_text()
    assert all(clip["id"] in gallery for clip in manifest["clips"])
    # no browser controls over the picture (they cover the clip's status lines): a play button below each clip
    assert "controls" not in gallery
    assert gallery.count("<video ") == gallery.count('<button type="button">Play</button>') == 4


def test_every_clip_is_audited_and_misleading_ones_are_marked_and_warned_about(built):
    """The manifest's audit is the observer's verdict on the clip's own summary; the gallery marks each misleading
    clip and the build prints one warning line for each, naming no on-screen label (the log would otherwise tell a
    researcher who pilots the study which labelled agent is better)."""
    from app.visible import VisibleClip, audit

    out, manifest, log, _ = built
    gallery = (out / "index.html").read_text()
    misleading = [clip for clip in manifest["clips"] if clip["audit"]["shows"] != "better"]
    for clip in manifest["clips"]:
        summary = json.loads((out / clip["summary"]).read_text())
        better_label = clip["labels"][clip["agents"].index(clip["better"])]
        shown = {key: value for key, value in clip["audit"].items() if key != "vote"}
        assert shown == audit(VisibleClip.of_summary(summary, clip["agents"], clip["labels"]), better_label)
        assert ("vote" in clip["audit"]) == (clip["solver"] == "representative")  # the vote that chose the clip
    warnings = [line for line in log if line.startswith("warning: clip ") and " is misleading" in line]
    assert len(warnings) == len(misleading) and gallery.count('<figure class="misleading">') == len(misleading)
    assert all(any(clip["id"] in line for line in warnings) for clip in misleading)
    assert misleading
    assert not any(label in line for line in log for clip in manifest["clips"] for label in clip["labels"])
    assert f"{len(misleading)} of {len(manifest['clips'])} clips are misleading" in gallery


def test_searches_in_parallel_give_the_same_bundle(built, tmp_path):
    _, manifest, _, study = built
    log = []
    assert json.loads(manifest_json(build_bundle(study, tmp_path / "parallel", log=log.append, workers=2))) == manifest
    assert len([line for line in log if line.startswith("search ") and not line.endswith("cached")]) == 4


def test_the_survey_server_accepts_the_bundle(built):
    from app.survey.bundle import load_bundle

    out, manifest, _, _ = built
    bundle = load_bundle(out)
    assert set(bundle.clips) == {clip["id"] for clip in manifest["clips"]}


def test_a_rebuild_reuses_cached_searches_and_clips(built):
    out, manifest, log, study = built
    assert not any(line.endswith(": cached") for line in log)
    again = []
    assert build_bundle(study, out, log=again.append).model_dump(mode="json") == manifest
    searches = [line for line in again if line.startswith("search ")]
    assert len(searches) == 4 and all(line.endswith(": cached") for line in searches)
    assert all(line.endswith(": cached") for line in again if line.startswith(("render ", "eval ")))


def test_a_changed_input_reruns_only_the_searches_it_touches(built):
    out, _, _, study = built
    changed = study.with_name("changed.toml")
    changed.write_text(study.read_text().replace('solver = "mcts"\nbudget = 300', 'solver = "mcts"\nbudget = 400'))
    log = []
    manifest = build_bundle(changed, out, log=log.append).model_dump(mode="json")
    searches = [line for line in log if line.startswith("search ")]
    assert sorted(line.endswith(": cached") for line in searches) == [False, True, True, True]
    assert [line for line in searches if not line.endswith(": cached")][0].startswith("search adaptive")
    assert json.loads((out / "manifest.json").read_text()) == manifest


def test_a_cached_search_that_no_longer_reproduces_is_run_again(built):
    out, _, _, study = built
    # a search of this study's first build: other tests add entries for changed studies to the same cache later
    cached = min((out / "cache" / "search").glob("*/summary-001.json"), key=lambda path: path.stat().st_mtime_ns)
    summary = json.loads(cached.read_text())
    summary["steps"][3]["agent_positions"][0][0] += 0.5  # as if the simulator had changed since
    cached.write_text(json.dumps(summary))
    log = []
    build_bundle(study, out, log=log.append)
    again = [line for line in log if "no longer re-simulates exactly" in line]
    assert len(again) == 1 and "steps[3].agent_positions[0][0]" in again[0]
    cached_step = json.loads(cached.read_text())["steps"][3]
    assert cached_step["agent_positions"][0][0] != summary["steps"][3]["agent_positions"][0][0]


def test_outcome_selection_shows_the_top_k_summary_with_the_largest_visible_contrast(built):
    """With select = "contrast" the clip is the summary of the search's top-K whose clip shows the largest
    visible difference (either way, no ground truth), not necessarily the best by reward."""
    from app.visible import Observer, VisibleClip

    out, manifest, _, _ = built
    clip = next(c for c in manifest["clips"] if c["scheme"] == "adaptive")
    shown = json.loads((out / clip["summary"]).read_text())
    [folder] = [
        folder
        for folder in (out / "cache" / "search").iterdir()
        if json.loads((folder / "inputs.json").read_text())["solver"] == "mcts"
        and json.loads((folder / "inputs.json").read_text())["budget"] == 300
    ]
    searched = [json.loads(p.read_text()) for p in sorted(folder.glob("summary-*.json"))]
    assert len(searched) > 1  # of the top 5, those whose trajectories ended within the budget

    def contrast(summary):
        first, second = VisibleClip.of_summary(summary, ["goal", "orca"], ["a", "b"]).scores(Observer()).values()
        return abs(first - second) if abs(first - second) >= Observer().tie_margin else 0.0

    assert contrast(shown) == max(contrast(s) for s in searched)
    assert shown == next(s for s in searched if contrast(s) == contrast(shown)) | {"solver": shown["solver"]}


def test_the_representative_clip_and_the_representativeness_of_the_fixed_scenario(built):
    """The representative scheme's clip comes from a drawn starting state and re-simulates exactly; the fixed
    scenario is measured against the training distribution, in the manifest, the log and the gallery."""
    from search.solvers.summary import verify

    out, manifest, log, _ = built
    clip = next(c for c in manifest["clips"] if c["scheme"] == "representative")
    assert clip["scenario"] == "training" and clip["solver"] == "representative"
    summary = json.loads((out / clip["summary"]).read_text())
    assert summary["scenario"]["name"].startswith("training#") and verify(out / clip["summary"]) == []
    vote = clip["audit"]["vote"]  # three states never decide a vote (p >= 1/4): a warning in the log and gallery
    assert vote["states"] <= 3 and not vote["decided"] and len(vote["won"]) == 2
    assert any(line.startswith(f"warning: clip {clip['id']} ") and "weak vote" in line for line in log)
    assert "WARNING: weak vote" in (out / "index.html").read_text()
    [report] = manifest["representativeness"]
    assert report["agents"] == ["goal", "orca"] and report["scenario"] == "paper-bl-tr"
    assert report["rollouts"] == 4 and report["distribution_vote"]["states"] == 3
    shares = report["first_looks_better"] + report["second_looks_better"] + report["no_difference"]
    assert shares == pytest.approx(1.0)
    direction = report["distribution_vote"]["direction"]
    assert report["disagrees"] == bool(direction and report["majority"] != direction)
    line = next(line for line in log if "paper-bl-tr, goal vs orca" in line)
    warned = report["disagrees"] and report["decided"]  # 4 rollouts decide nothing: at most 1 in 16 by chance
    assert line.startswith("warning: unrepresentative" if warned else "representativeness")
    assert "How representative the study" in (out / "index.html").read_text()
