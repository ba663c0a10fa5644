"""Bundles: refused at start-up, with the problem named, when they cannot serve the study."""

from __future__ import annotations

import json
import shutil

import pytest

from app.survey.bundle import BundleError, check_study_against_bundle, load_bundle
from app.survey.study import parse_study
from tests.support.survey import VIDEO_CHECK, study_text


@pytest.fixture
def bundle_copy(bundle_dir, tmp_path):
    root = tmp_path / "bundle"
    shutil.copytree(bundle_dir, root)
    return root


def edit_manifest(root, change) -> None:
    manifest = json.loads((root / "manifest.json").read_text())
    change(manifest)
    (root / "manifest.json").write_text(json.dumps(manifest))


def test_the_test_bundle_serves_the_paper_study(bundle_dir):
    check_study_against_bundle(parse_study(study_text()), load_bundle(bundle_dir))


def test_missing_manifest_and_wrong_format(tmp_path, bundle_copy):
    with pytest.raises(BundleError, match="no manifest.json"):
        load_bundle(tmp_path / "nowhere")
    edit_manifest(bundle_copy, lambda m: m.update(format="foil.bundle/9"))
    with pytest.raises(BundleError, match="this server reads 'foil.bundle/1'"):
        load_bundle(bundle_copy)


def test_changed_file_missing_file_and_escaping_path(bundle_copy):
    (bundle_copy / "clips" / "000.mp4").write_bytes(b"not the clip")
    (bundle_copy / "clips" / "001.mp4").unlink()

    def escape(manifest):
        manifest["clips"][2]["file"] = "../../etc/passwd"

    edit_manifest(bundle_copy, escape)
    with pytest.raises(BundleError) as error:
        load_bundle(bundle_copy)
    message = str(error.value)
    assert "000.mp4' does not match its sha256" in message
    assert "001.mp4' is missing" in message
    assert "'../../etc/passwd' lies outside the bundle" in message


def test_manifest_entry_with_bad_ground_truth(bundle_copy):
    edit_manifest(bundle_copy, lambda m: m["clips"][0].update(better="someone-else"))
    with pytest.raises(BundleError, match="clips.0: Value error, better 'someone-else' is not one of its agents"):
        load_bundle(bundle_copy)


def test_a_clip_the_study_needs_is_missing(bundle_copy):
    edit_manifest(
        bundle_copy,
        lambda m: m.update(
            clips=[c for c in m["clips"] if c["scheme"] != "schemenfirstsecret" or c["scenario"] != "scenariotwosecret"]
        ),
    )
    with pytest.raises(
        BundleError,
        match="needs a clip of scheme 'schemenfirstsecret', scenario "
        "'scenariotwosecret', agents 'agentlowsecret' and 'agentmedsecret'",
    ):
        check_study_against_bundle(parse_study(study_text()), load_bundle(bundle_copy))


def test_a_bundle_of_another_study_says_to_rebuild_it_and_lists_ten_problems_at_most(bundle_copy):
    edit_manifest(bundle_copy, lambda m: m.update(clips=[c for c in m["clips"] if c["scheme"] != "schemenfirstsecret"]))
    with pytest.raises(BundleError) as refused:
        check_study_against_bundle(parse_study(study_text()), load_bundle(bundle_copy))
    lines = str(refused.value).splitlines()
    count = int(lines[0].split("(")[1].split(" ")[0])
    assert lines[0].startswith("the bundle does not match the study (") and "rebuild it with foil bundle" in lines[0]
    assert count > 10 and len(lines) == 12 and lines[-1] == f"... and {count - 10} more"


def test_ranking_clips_must_label_each_robot_once(bundle_copy):
    def relabel(manifest):
        clip = next(c for c in manifest["clips"] if "agenthighsecret" in c["agents"])
        pairs = zip(clip["agents"], clip["labels"], strict=True)
        clip["labels"] = ["Robot 9" if agent == "agenthighsecret" else label for agent, label in pairs]

    edit_manifest(bundle_copy, relabel)
    with pytest.raises(BundleError, match="a ranking needs one label per agent"):
        check_study_against_bundle(parse_study(study_text()), load_bundle(bundle_copy))


def test_a_video_attention_checks_clip_must_be_in_the_bundle(bundle_dir):
    bundle = load_bundle(bundle_dir)
    present = parse_study(study_text(contact=VIDEO_CHECK.format(scheme="schemenfirstsecret")))
    check_study_against_bundle(present, bundle)
    missing = parse_study(study_text(contact=VIDEO_CHECK.format(scheme="schemeadaptivesecret")))
    with pytest.raises(
        BundleError,
        match=r"attention_checks\[0\] \(a video attention check's clip\) needs a clip of "
        "scheme 'schemeadaptivesecret', scenario 'scenarioexamplesecret', agents "
        "'agentlowsecret' and 'agenthighsecret'; the manifest has none",
    ):
        check_study_against_bundle(missing, bundle)


def test_the_server_does_not_start_without_the_video_attention_checks_clip(tmp_path, bundle_dir):
    from app.web.main import create_app
    from app.web.settings import ServerSettings

    study = tmp_path / "study.toml"
    study.write_text(study_text(contact=VIDEO_CHECK.format(scheme="schemeadaptivesecret")))
    settings = ServerSettings(
        bundle_dir=bundle_dir, study_file=study, database_url=f"sqlite:///{tmp_path / 'db.sqlite3'}"
    )
    with pytest.raises(BundleError, match=r"attention_checks\[0\] \(a video attention check's clip\)"):
        create_app(settings)
