"""The demo's representative clips tell the truth: built with the demo study's own searches from the shipped
agents, every one of them shows the better robot as better, and re-simulates exactly."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from search.bundle.build import build_bundle
from search.bundle.searches import plan_clips, search_inputs, search_job
from search.bundle.spec import load_build

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "studies" / "demo.toml"


def representative_part(text: str) -> str:
    """The demo study with only its representative set of clips (the same searches, evaluations and labels)."""
    head, *sets = text.split("[[build.sets]]")
    kept = [block for block in sets if 'schemes = ["representative"]' in block]
    assert len(kept) == 1
    return head + "[[build.sets]]" + kept[0]


def test_every_representative_clip_of_the_demo_shows_the_better_robot(tmp_path):
    from search.solvers.summary import verify

    study = tmp_path / "demo.toml"
    study.write_text(representative_part(DEMO.read_text()))
    demo_spec, _ = load_build(DEMO)
    demo_searches = {
        json.dumps(search_inputs(search_job(job)), sort_keys=True)
        for job in plan_clips(demo_spec)
        if job.scheme.name == "representative"
    }
    spec, _ = load_build(study)
    assert {json.dumps(search_inputs(search_job(job)), sort_keys=True) for job in plan_clips(spec)} == demo_searches
    manifest = build_bundle(study, tmp_path / "out", log=lambda line: None)
    clips = [clip for clip in manifest.clips if clip.scheme == "representative"]
    assert len(clips) == 6  # three pairs, drawn once for each part
    for clip in clips:
        assert clip.audit.shows == "better", clip.audit.why
        assert verify(tmp_path / "out" / clip.summary) == []
    assert {report["scenario"] for report in manifest.representativeness} == set()  # no fixed scenario here
