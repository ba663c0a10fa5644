"""`foil prereg`: the analysis fixed before the data. It writes prereg.md (for a registry such as OSF or
AsPredicted) and prereg.json (for `foil report --prereg`, which lists every way the data differ from it), both
naming the study file and the bundle's manifest by their SHA-256."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

from app.analysis.exclusions import REASONS, ExclusionRules
from app.analysis.power import chance, tasks
from app.survey.assignment import conditions
from app.survey.study import Study, parse_study

VERSION = 1


def text_hash(text: str) -> str:
    return "sha256:" + hashlib.sha256(text.encode("utf-8")).hexdigest()


def file_hash(path: Path) -> str:
    return "sha256:" + hashlib.sha256(path.read_bytes()).hexdigest()


def _rules(rules: ExclusionRules) -> dict[str, Any]:
    return {
        "min_seconds": rules.min_seconds,
        "median_fraction": None if rules.min_seconds is not None else rules.median_fraction,
        "include_kinds": sorted(rules.include_kinds),
    }


def _rules_text(fixed: dict[str, Any]) -> str:
    rules = fixed["exclusions"]
    if rules["min_seconds"] is not None:
        time = f"completed in under {rules['min_seconds']:g} s" if rules["min_seconds"] else "no time rule"
    else:
        time = f"completed in under {rules['median_fraction']:.3g} of the median completion time"
    kinds = ", ".join(rules["include_kinds"]) or "none"
    return f"{time}; pilots and bots analysed: {kinds}"


def plan(study_text: str, study: Study, manifest: Path, participants: int, rules: ExclusionRules) -> dict[str, Any]:
    """What the preregistration fixes, as data."""
    design = study.design
    schemes = ", ".join(design.schemes)
    return {
        "version": VERSION,
        "study": study.study.id,
        "study_file": text_hash(study_text),
        "bundle_manifest": file_hash(manifest),
        "participants": participants,
        "exclusions": _rules(rules),
        "hypotheses": [
            f"{task}: the accuracy of the {task} answers differs between the schemes {schemes} "
            f"(two-sided, alpha 0.05); each scheme's accuracy differs from chance ({chance(study, task):.3g})"
            for task in tasks(study)
        ],
        "design": {
            "schemes": list(design.schemes),
            "scheme_factor": design.scheme_factor,
            "scenarios": list(design.scenarios),
            "scheme_scenarios": {k: list(v) for k, v in design.scheme_scenarios.items()},
            "counterbalance_scenarios": design.counterbalance_scenarios,
            "counterbalance_scheme_order": design.counterbalance_scheme_order,
            "conditions": len(conditions(study)),
            "parts": [
                {"kind": part.kind, "pairs": [list(p) for p in part.pairs]}
                if part.kind == "pairwise"
                else {"kind": part.kind, "agents": list(part.agents)}
                for part in study.parts
            ],
        },
        "model": (
            "per part, logistic regression correct ~ scheme (+ pair + scenario where the part has more than one), "
            "Firth-penalised, standard errors clustered by participant and by clip (two-way, CR2 small-sample "
            "correction), t tests on min(participants, clips) - 1 degrees of freedom; the "
            "schemes differ: Wald F test; R: glmer(correct ~ scheme + (1 | participant) + (1 | clip), "
            "family = binomial) for the mixed model it stands in for"
        ),
    }


def markdown(fixed: dict[str, Any]) -> str:
    design = fixed["design"]
    lines = [
        f"# Preregistration: study {fixed['study']}",
        "",
        f"- Study file: {fixed['study_file']}",
        f"- Bundle manifest: {fixed['bundle_manifest']}",
        f"- Planned participants (analysed, after exclusions): {fixed['participants']}",
        "",
        "## Hypotheses",
        "",
        *(f"- {h}" for h in fixed["hypotheses"]),
        "",
        "## Design",
        "",
        f"- Schemes: {', '.join(design['schemes'])} ({design['scheme_factor']}-subjects)",
        f"- Scenarios: {', '.join(design['scenarios'])}"
        + "".join(f"; {s}: {', '.join(v)}" for s, v in design["scheme_scenarios"].items()),
        f"- Counterbalancing: scenarios {'yes' if design['counterbalance_scenarios'] else 'no'}, scheme order "
        f"{'yes' if design['counterbalance_scheme_order'] else 'no'}; {design['conditions']} conditions",
        *(
            f"- Part {n}: {part['kind']}, "
            + (
                "pairs " + ", ".join(" vs ".join(p) for p in part["pairs"])
                if part["kind"] == "pairwise"
                else "ranks " + ", ".join(part["agents"])
            )
            for n, part in enumerate(design["parts"], 1)
        ),
        "",
        "## Exclusions",
        "",
        *(f"- {text}" for text in REASONS.values()),
        f"- Completion time and kinds: {_rules_text(fixed)}",
        "",
        "## Analysis",
        "",
        fixed["model"] + ".",
        "",
    ]
    return "\n".join(lines)


def run_prereg(*, study_path: str, bundle: str, out: str, participants: int, rules: ExclusionRules) -> int:
    """`foil prereg`: writes DIR/prereg.md and DIR/prereg.json."""
    path = Path(study_path)
    manifest = Path(bundle) / "manifest.json"
    if not path.is_file():
        raise ValueError(f"no study file {study_path}")
    if not manifest.is_file():
        raise ValueError(f"no manifest.json in bundle {bundle}: give the bundle the study will be served from")
    if participants < 1:
        raise ValueError(f"--participants {participants}: give the planned number of participants (foil power)")
    text = path.read_text(encoding="utf-8")
    fixed = plan(text, parse_study(text, source=str(path)), manifest, participants, rules)
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "prereg.json").write_text(json.dumps(fixed, indent=2) + "\n", encoding="utf-8")
    (folder / "prereg.md").write_text(markdown(fixed), encoding="utf-8")
    print(f"preregistration: {folder / 'prereg.md'} and {folder / 'prereg.json'}")
    return 0


def deviations(
    fixed: dict[str, Any], study_text: str, manifest: Path | None, analysed: int, rules: ExclusionRules
) -> list[str]:
    """Every way the analysed data differ from the preregistration (empty: none)."""
    found = []
    if text_hash(study_text) != fixed["study_file"]:
        found.append("the study file differs from the preregistered one (its SHA-256 differs)")
    if manifest is None or not manifest.is_file():
        found.append("the bundle the study was served from is not known, so its manifest cannot be checked")
    elif file_hash(manifest) != fixed["bundle_manifest"]:
        found.append("the bundle's manifest.json differs from the preregistered one (its SHA-256 differs)")
    if analysed < fixed["participants"]:
        found.append(f"{analysed} participants analysed, fewer than the {fixed['participants']} planned")
    elif analysed > fixed["participants"]:
        found.append(f"{analysed} participants analysed, more than the {fixed['participants']} planned")
    if _rules(rules) != fixed["exclusions"]:
        found.append(
            f"exclusions differ: {_rules_text({'exclusions': _rules(rules)})}; preregistered {_rules_text(fixed)}"
        )
    return found
