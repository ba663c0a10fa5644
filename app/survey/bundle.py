"""The study bundle (manifest.json, format `foil.bundle/1`) and how a study's clips are found in it.

A clip is named by (scheme, scenario, pair of agents); the manifest entries whose scheme and scenario are equal
and whose `agents` are that pair in any order all match. Everything is checked once at start-up: files inside the
bundle (a clip's, or each of its reels'), checksums, and that every clip the study needs is there and can be shown
where the study shows it (a pair of reels only on a pairwise or ranking part's screens).
"""

from __future__ import annotations

import itertools
import json
from collections import defaultdict
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import NamedTuple

from pydantic import ValidationError

from app.formats import MANIFEST_FORMAT, Manifest, ManifestClip, sha256_file
from app.survey.study import ClipRef, Study
from app.visible import CROWD, World


class BundleError(ValueError):
    """A bundle the server cannot serve; the message names the problem."""


@dataclass(frozen=True)
class Bundle:
    root: Path
    clips: dict[str, ManifestClip]  # by id
    paths: dict[str, Path]  # sha256 -> file (a clip's or a reel's), what /clips/{sha256}.mp4 serves
    world: World = CROWD  # the world the clips show: its rule and the words its pages use (the crowd's by default)
    undecided: frozenset[frozenset[str]] = frozenset()  # pairs the ground truth cannot tell apart (close pairs)

    def matching(self, scheme: str, scenario: str, agents: tuple[str, str], part: str = "") -> list[ManifestClip]:
        """The two-agent clips of a scheme, scenario and pair (in either order), in id order; with `part`, those
        made for that part where there are any (a clip whose entry names no parts serves every part)."""
        clips = list(self._pairs.get((scheme, scenario, frozenset(agents)), ()))
        made_for = [clip for clip in clips if not clip.parts or part in clip.parts]
        return made_for if part and made_for else clips

    @cached_property
    def _pairs(self) -> dict[tuple[str, str, frozenset[str]], list[ManifestClip]]:
        """Two-agent clips by (scheme, scenario, set of agents), each list in id order: a plan looks up a clip
        for every screen it builds."""
        index = defaultdict(list)
        for clip in sorted(self.clips.values(), key=lambda clip: clip.id):
            if len(clip.agents) == 2:
                index[(clip.scheme, clip.scenario, frozenset(clip.agents))].append(clip)
        return dict(index)


def load_bundle(root: str | Path) -> Bundle:
    root = Path(root).resolve()
    manifest_path = root / "manifest.json"
    try:
        data = json.loads(manifest_path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise BundleError(f"no manifest.json in bundle {root}") from None
    except (OSError, json.JSONDecodeError) as error:
        raise BundleError(f"cannot read {manifest_path}: {error}") from None
    try:
        manifest = Manifest.model_validate(data)
    except ValidationError as error:
        problems = [f"{'.'.join(str(x) for x in e['loc'])}: {e['msg']}" for e in error.errors()]
        raise BundleError(f"{manifest_path} is not a valid manifest:\n" + "\n".join(problems)) from None
    if manifest.format != MANIFEST_FORMAT:
        raise BundleError(f"{manifest_path}: format is {manifest.format!r}, this server reads {MANIFEST_FORMAT!r}")
    clips: dict[str, ManifestClip] = {}
    paths: dict[str, Path] = {}
    problems = []
    for clip in manifest.clips:
        if clip.id in clips:
            problems.append(f"clip id {clip.id!r} appears twice")
        clips[clip.id] = clip
        for file, sha256 in [(reel.file, reel.sha256) for reel in clip.reels] or [(clip.file, clip.sha256)]:
            path = (root / file).resolve()
            if not path.is_relative_to(root):
                problems.append(f"clip {clip.id!r}: file {file!r} lies outside the bundle")
            elif not path.is_file():
                problems.append(f"clip {clip.id!r}: file {file!r} is missing")
            elif sha256_file(path) != sha256.lower():
                problems.append(f"clip {clip.id!r}: {file!r} does not match its sha256 (changed after bundling?)")
            else:
                paths[sha256.lower()] = path
    if problems:
        raise BundleError(f"bundle {root}:\n" + "\n".join(problems))
    undecided = frozenset(frozenset(pair.agents) for pair in manifest.close_pairs if not pair.decided)
    return Bundle(root=root, clips=clips, paths=paths, world=manifest.shown_world(), undecided=undecided)


def _part_scenarios(study: Study, part_index: int, scheme: str) -> list[str]:
    return list(dict.fromkeys(study.part_scenario(part_index, r, scheme) for r in study.rotations()))


class NeededClip(NamedTuple):
    """A clip the study can show: what it is, where the study asks for it, and the kind of part that shows it
    ("pairwise" or "ranking"; "" for the instructions' example and a video attention check)."""

    ref: ClipRef
    where: str
    part: str = ""


def required_clips(study: Study) -> list[NeededClip]:
    """Every clip the study can show under any condition, each with where the study asks for it."""
    refs = []
    if study.example is not None:
        refs.append(NeededClip(study.example, "[example]"))
    for p, part in enumerate(study.parts):
        pairs = part.pairs if part.kind == "pairwise" else list(itertools.combinations(part.agents, 2))
        for scheme in study.design.schemes:
            for scenario in _part_scenarios(study, p, scheme):
                for pair in pairs:
                    ref = ClipRef(scheme=scheme, scenario=scenario, agents=pair)
                    refs.append(NeededClip(ref, f"parts[{p}]", part.kind))
    for c, check in enumerate(study.attention_checks):
        if check.clip is not None:  # a video attention check
            refs.append(NeededClip(check.clip, f"attention_checks[{c}] (a video attention check's clip)"))
    return refs


def check_study_against_bundle(study: Study, bundle: Bundle) -> None:
    """Refuse a bundle that lacks a clip the study needs, shows a pair of reels anywhere but on a pairwise or ranking
    part's screens, or whose ranking clips label one agent two ways."""
    problems = []
    for ref, where, kind in required_clips(study):
        found = bundle.matching(ref.scheme, ref.scenario, ref.agents, kind)
        if not found:
            problems.append(
                f"{where} needs a clip of scheme {ref.scheme!r}, scenario {ref.scenario!r}, agents "
                f"{ref.agents[0]!r} and {ref.agents[1]!r}; the manifest has none"
            )
        # The example and a video attention check show one video each: reels (two videos per clip) are shown on
        # the screens of a pairwise or ranking part only (a ranking round lists each of its reels).
        elif kind not in ("pairwise", "ranking") and (reels := [clip.id for clip in found if clip.reels]):
            problems.append(
                f"{where} would show clips of reels ({', '.join(map(repr, reels))}) of scheme {ref.scheme!r}; only "
                "pairwise and ranking parts show reels, the example and a video attention check show clips of both "
                "agents together"
            )
    for p, part in enumerate(study.parts):
        if part.kind != "ranking":
            continue
        for scheme in study.design.schemes:
            for scenario in _part_scenarios(study, p, scheme):
                labels: dict[str, set[str]] = {}
                for pair in itertools.combinations(part.agents, 2):
                    for clip in bundle.matching(scheme, scenario, pair):
                        for agent, label in zip(clip.agents, clip.labels, strict=True):
                            labels.setdefault(agent, set()).add(label)
                if any(len(found) > 1 for found in labels.values()) or len(
                    {frozenset(found) for found in labels.values()}
                ) != len(labels):
                    shown = {agent: sorted(found) for agent, found in labels.items()}
                    problems.append(
                        f"parts[{p}]: the ranking clips of scheme {scheme!r}, scenario {scenario!r} label the "
                        f"agents {shown}; a ranking needs one label per agent and a different label for each"
                    )
    if problems:
        distinct = list(dict.fromkeys(problems))
        listed = distinct if len(distinct) <= 10 else [*distinct[:10], f"... and {len(distinct) - 10} more"]
        raise BundleError(
            f"the bundle does not match the study ({len(distinct)} problem{'s' if len(distinct) > 1 else ''}): it was "
            "built from another study file, or the study changed since: rebuild it with foil bundle STUDY.toml --out "
            "BUNDLE (clips already built are reused)\n" + "\n".join(listed)
        )
