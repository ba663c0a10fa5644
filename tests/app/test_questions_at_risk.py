"""Questions at risk in a bundle, counted from its manifest, and `foil power --bundle` (the app's side)."""

from __future__ import annotations

import json

import pytest

from app.formats import Manifest


def _manifest() -> Manifest:
    clip = {"file": "clips/x.mp4", "sha256": "0" * 64, "scenario": "s", "labels": ["Robot 1", "Robot 2"]}
    vote = {"states": 9, "won": [4, 5], "no_majority": 0, "sign_test_p": 1.0, "decided": False}
    clips = [
        clip | {"id": "a", "scheme": "nfirst", "agents": ["lo", "med"], "better": "med", "parts": ["pairwise"],
                "audit": {"shows": "better", "why": "med reached its goal"}},
        clip | {"id": "b", "scheme": "nfirst", "agents": ["med", "hi"], "better": "hi",
                "parts": ["pairwise", "example"], "audit": {"shows": "tie", "why": "both reached their goals"}},
        clip | {"id": "c", "scheme": "representative", "agents": ["lo", "hi"], "better": "hi", "parts": ["pairwise"],
                "audit": {"shows": "better", "why": "hi reached its goal", "vote": vote}},
    ]  # fmt: skip
    close = [{"agents": ["med", "hi"], "difference": -0.4, "ci95": [-1.5, 0.7], "p": 1.0, "episodes": 800,
              "decided": False}]  # fmt: skip
    return Manifest.model_validate({"format": "foil.bundle/1", "clips": clips, "close_pairs": close})


def test_questions_at_risk_per_part_and_scheme():
    assert _manifest().questions_at_risk() == [
        {"part": "pairwise", "scheme": "nfirst", "clips": 2, "undecided": 1, "weak_vote": 0, "misleading": 1},
        {"part": "pairwise", "scheme": "representative", "clips": 1, "undecided": 0, "weak_vote": 1, "misleading": 0},
    ]


def test_foil_power_from_a_bundle_says_what_is_wrong(tmp_path):
    from app.analysis.power import bundle_accuracies
    from app.survey.study import parse_study
    from tests.support.survey import study_text

    study = parse_study(study_text())
    with pytest.raises(ValueError, match="no manifest.json there"):
        bundle_accuracies(str(tmp_path), study, 0.85)
    (tmp_path / "manifest.json").write_text(json.dumps(json.loads(_manifest().model_dump_json())))
    with pytest.raises(ValueError, match="--shown-right 1.2"):
        bundle_accuracies(str(tmp_path), study, 1.2)
    with pytest.raises(ValueError, match="no audited pairwise clip of"):
        bundle_accuracies(str(tmp_path), study, 0.85)  # the test study's schemes are not the manifest's


def test_foil_power_expects_the_accuracies_the_bundle_predicts(tmp_path, capsys):
    """A scheme whose clips show the better agent is expected at 85%, one whose clip rests on an undecided pair
    or shows a tie at 50%; `foil power --bundle` simulates the study with them."""
    from app.analysis.power import run_power
    from app.survey.study import parse_study
    from tests.support.survey import study_text

    (tmp_path / "study.toml").write_text(study_text())
    first, second = parse_study(study_text()).design.schemes
    manifest = json.loads(_manifest().model_dump_json())
    for clip, scheme in zip(manifest["clips"], (first, first, second), strict=True):
        clip["scheme"] = scheme
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    assert run_power(study_path=str(tmp_path / "study.toml"), pairwise=None, ranking=None, pilot=None,
                     participant_sd=1.0, clip_sd=0.5, largest=8, studies=10, seed=0,
                     bundle=str(tmp_path)) == 0  # fmt: skip
    out = capsys.readouterr().out
    # first: one clear clip (85%) and one tie (50%); second: one clear clip
    assert "expected from the bundle's audit" in out and f"{first} 0.68, {second} 0.85" in out
