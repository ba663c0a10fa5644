"""`foil serve` refuses a broken bundle or study before it starts, as a real process, and names the problem."""

from __future__ import annotations

import json
import shutil

import pytest

from tests.support.live_server import foil, free_port
from tests.support.survey import study_text

pytestmark = pytest.mark.slow  # a foil serve process per broken bundle


def broken_checksum(bundle):
    clip = json.loads((bundle / "manifest.json").read_text())["clips"][3]
    (bundle / clip["file"]).write_bytes(b"not the clip that was bundled")
    return f"clip {clip['id']!r}: {clip['file']!r} does not match its sha256"


def missing_clip(bundle):
    clip = json.loads((bundle / "manifest.json").read_text())["clips"][0]
    (bundle / clip["file"]).unlink()
    return f"clip {clip['id']!r}: file {clip['file']!r} is missing"


def manifest_for_another_study(bundle):
    manifest = json.loads((bundle / "manifest.json").read_text())
    manifest["clips"] = [c for c in manifest["clips"] if c["scheme"] != "schemenfirstsecret"]
    (bundle / "manifest.json").write_text(json.dumps(manifest))
    return "needs a clip of scheme 'schemenfirstsecret'"


def unreadable_manifest(bundle):
    (bundle / "manifest.json").write_text('{"format": "foil.bundle/1", "clips": [')
    return "cannot read"


def missing_manifest(bundle):
    (bundle / "manifest.json").unlink()
    return "no manifest.json in bundle"


@pytest.mark.parametrize(
    "breaking", [broken_checksum, missing_clip, manifest_for_another_study, unreadable_manifest, missing_manifest]
)
def test_foil_serve_refuses_a_broken_bundle_naming_the_problem(tmp_path, bundle_dir, breaking):
    bundle = shutil.copytree(bundle_dir, tmp_path / "bundle")
    expected = breaking(bundle)
    study = tmp_path / "study.toml"
    study.write_text(study_text())
    server = foil("serve", "--bundle", str(bundle), "--study", str(study), "--port", str(free_port()), cwd=tmp_path)
    output, _ = server.communicate(timeout=60)
    assert server.returncode == 2, output
    assert "foil serve: error:" in output and expected in output, output
    assert "Uvicorn running" not in output
