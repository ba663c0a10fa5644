"""The bundle's index.html: a static gallery of every clip for the researcher, with what participants never see
(agents, ground truth, audits, votes, the representativeness reports and the close pairs). The offline side's one
Jinja environment, over gallery.html beside this module."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from app.formats import ManifestClip
from app.visible import World
from search.bundle.clips import vote_warnings
from search.bundle.representativeness import describe_representativeness
from search.bundle.truth import PairedComparison, describe_close_pair


def write_gallery(
    out: Path,
    clips: list[ManifestClip],
    evaluations: dict[str, dict[str, Any]],
    scenario_reports: list[dict[str, Any]],
    world: World,
    close: list[dict[str, Any]] | None = None,
) -> None:
    """A static page of every clip with what participants never see: agents, ground truth, outcomes, reward, and
    the close pairs (manifest `close_pairs`), whose undecided ones no clip marks a better agent for. It speaks in
    the world's words: outcome rates where its clips end in outcomes, its visible score where it declares one."""
    from jinja2 import Environment, FileSystemLoader, StrictUndefined

    from search.core.contrast import describe_vote

    templates = Environment(
        loader=FileSystemLoader(Path(__file__).parent),
        autoescape=True,
        undefined=StrictUndefined,
        keep_trailing_newline=True,
    )
    page = templates.get_template("gallery.html").render(
        clips=clips,
        evaluations=evaluations,
        shows=world.words.shown if world.has_outcomes() or world.score is None else f"each one's {world.score.name}",
        rates=world.has_outcomes() and all("success_rate" in e for e in evaluations.values()),
        score=world.score.name if world.score is not None else "",
        zip=zip,
        scenarios=scenario_reports,
        describe=describe_representativeness,
        describe_vote=describe_vote,
        vote_warnings=vote_warnings,
        close=close or [],
        describe_close=lambda pair: describe_close_pair(PairedComparison.from_manifest(pair)),
    )
    (out / "index.html").write_text(page, encoding="utf-8")
