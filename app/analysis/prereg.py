"""`foil prereg`: the analysis fixed before the data. It writes prereg.md (for a registry such as OSF or
AsPredicted) and prereg.json (for `foil report --prereg`, which lists every way the data differ from it), both
naming the study file and the bundle's manifest by the SHA-256 of their bytes (what `sha256sum` prints) and the
versions of Foil and of the report's model."""

from __future__ import annotations

import json
from importlib.metadata import PackageNotFoundError, version
from itertools import groupby
from pathlib import Path
from typing import Any

from app.analysis.design import GUESS, UPDATE_MEASURES, chance, tasks
from app.analysis.exclusions import REASONS, ExclusionRules
from app.analysis.model import MODEL_VERSION
from app.analysis.source import sha256
from app.survey.assignment import conditions
from app.survey.study import Study, parse_study

VERSION = 2  # 2: Foil's and the model's versions; hashes of the files' bytes (1: of the text with LF line ends)
ANSWERS = {"pairwise": "pairwise answers", "ranking": "rankings' pairwise orderings"}


def foil_version() -> str | None:
    """The installed Foil's version (None when run from a checkout that was never installed)."""
    try:
        return version("foil")
    except PackageNotFoundError:
        return None


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


def plan(study_file: bytes, study: Study, manifest: Path, participants: int, rules: ExclusionRules) -> dict[str, Any]:
    """What the preregistration fixes, as data."""
    design = study.design
    schemes = ", ".join(design.schemes)
    untestable = untestable_tasks(study, participants)
    return {
        "version": VERSION,
        "foil": foil_version(),
        "model_version": MODEL_VERSION,
        "study": study.study.id,
        "study_file": sha256(study_file),
        "bundle_manifest": sha256(manifest.read_bytes()),
        "participants": participants,
        "exclusions": _rules(rules),
        "hypotheses": [
            f"{task}: the accuracy of the {ANSWERS[task]} differs between the schemes {schemes} (the primary test, "
            "two-sided, alpha 0.05, unadjusted); secondary, each Holm-adjusted as a family: each scheme's accuracy "
            f"differs from chance ({0.5 if task == 'ranking' else chance(study, task):.3g}), and with three schemes "
            "or more each pair of schemes differs"
            if task not in untestable
            else f"{task}: no test that the schemes differ is preregistered, as this design cannot run it: "
            f"{untestable[task]}. The report describes the part's accuracies and their intervals alone"
            for task in tasks(study)
        ]
        + _update_hypotheses(study),
        "untestable": untestable,
        "design": {
            "schemes": list(design.schemes),
            "scheme_factor": design.scheme_factor,
            "scenarios": list(design.scenarios),
            "scheme_scenarios": {k: list(v) for k, v in design.scheme_scenarios.items()},
            "counterbalance_scenarios": design.counterbalance_scenarios,
            "counterbalance_scheme_order": design.counterbalance_scheme_order,
            "conditions": len(conditions(study)),
            **_update_design(study),
            "parts": [
                {"kind": part.kind, "pairs": [list(p) for p in part.pairs]}
                if part.kind == "pairwise"
                else {"kind": part.kind, "agents": list(part.agents)}
                for part in study.parts
            ],
        },
        "model": (
            "per part, logistic regression correct ~ scheme (+ pair + scenario where the part has more than one), "
            "Firth-penalised, estimating population-averaged accuracies and odds ratios; cluster-robust standard "
            "errors (CR2) by participant, by clip and by both, each test reading the largest of the three; t tests "
            "on Satterthwaite degrees of freedom and, for the schemes together, the approximate Hotelling T² test "
            "(HTZ), as R's clubSandwich computes them; a scheme with fewer than two clips, or a test with fewer than "
            "2 degrees of freedom, is reported untestable (a contrast then by an exact permutation test of its clips "
            "within scenarios, where it has at least 20 arrangements); a ranking part by its pairwise orderings"
        ),
    }


def _update_hypotheses(study: Study) -> list[str]:
    """A study of updates: what the report estimates of its update pairs (none for other studies)."""
    if not study.design.updates:
        return []

    return [
        "updates: the pairwise accuracy above is of the compare answers on the update pairs the ground truth decides; "
        f"per scheme, each of {'; '.join(UPDATE_MEASURES)} is estimated with its 95% interval and tested against "
        f"guessing one of the three answers ({GUESS:.3g}), by the same model, and the schemes compared on it "
        "(secondary, descriptive of the bias to call an update better)"
    ]


def _update_design(study: Study) -> dict[str, Any]:
    """The update pairs (earlier, later) and controls of a study of updates; nothing for other studies."""
    design = study.design
    if not design.updates:
        return {}
    return {"updates": [list(pair) for pair in design.updates], "controls": [list(pair) for pair in design.controls]}


def _update_lines(design: dict[str, Any]) -> list[str]:
    """prereg.md's line on a study's update pairs and controls; none for other studies."""
    if not design.get("updates"):
        return []
    controls = ", ".join(" and ".join(pair) for pair in design["controls"]) or "none"
    updates = ", ".join(" to ".join(pair) for pair in design["updates"])
    return [f"- Updates (earlier to later): {updates}; controls: {controls}"]


def untestable_tasks(study: Study, participants: int) -> dict[str, str]:
    """Each part's task whose primary test (the schemes differ) this design cannot run, with the report's words for
    why: its model fitted to one simulated study of the planned participants, every scheme at 75% (a scheme with
    too few clips, or a test with too few degrees of freedom, is untestable whatever the answers)."""
    from app.analysis.simulation import MEASURES, Assumptions, simulated_fits  # numpy: not at the server's start

    assume = Assumptions({scheme: 0.75 for scheme in study.design.schemes})
    found = {}
    for task in tasks(study):
        fitted = simulated_fits(study, task, participants, assume, 1, 0)[MEASURES[task][0]][0]
        if fitted.estimable and fitted.scheme_p is None:
            why = fitted.scheme_test.removeprefix("not tested: ")
            found[task] = f"in a simulated study of {participants} participants, {why}"
    return found


def markdown(fixed: dict[str, Any]) -> str:
    design = fixed["design"]
    lines = [
        f"# Preregistration: study {fixed['study']}",
        "",
        f"- Study file: {fixed['study_file']}",
        f"- Bundle manifest: {fixed['bundle_manifest']}",
        f"- Foil {fixed['foil'] or '(version unknown)'}, the report's model version {fixed['model_version']}",
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
        *_update_lines(design),
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
    raw = path.read_bytes()
    fixed = plan(raw, parse_study(raw.decode("utf-8"), source=str(path)), manifest, participants, rules)
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "prereg.json").write_text(json.dumps(fixed, indent=2) + "\n", encoding="utf-8")
    (folder / "prereg.md").write_text(markdown(fixed), encoding="utf-8")
    print(f"preregistration: {folder / 'prereg.md'} and {folder / 'prereg.json'}")
    return 0


def deviations(
    fixed: dict[str, Any],
    study_text: str,
    manifest: Path | None,
    analysed: int,
    rules: ExclusionRules,
    starts: list[dict[str, Any]] | None = None,
) -> list[str]:
    """Every way the analysed data differ from the preregistration (empty: none). `study_text` is the study file
    the server stored, `starts` what each server start served (`study_starts`), so an edit reverted before the
    report is still listed."""
    found = []
    study_file = _preregistered_study(fixed, study_text)
    if sha256(study_text.encode("utf-8")) != study_file:
        found.append(
            f"the study file differs from the preregistered one ({sha256(study_text.encode('utf-8'))}, "
            f"preregistered {fixed['study_file']})"
        )
    if manifest is None or not manifest.is_file():
        found.append("the bundle the study was served from is not known, so its manifest cannot be checked")
    elif sha256(manifest.read_bytes()) != fixed["bundle_manifest"]:
        found.append(
            f"the bundle's manifest.json differs from the preregistered one ({sha256(manifest.read_bytes())}, "
            f"preregistered {fixed['bundle_manifest']})"
        )
    manifest_now = sha256(manifest.read_bytes()) if manifest is not None and manifest.is_file() else None
    found += _served(starts or [], "study_file", study_file, "a study file", sha256(study_text.encode("utf-8")))
    found += _served(starts or [], "bundle_manifest", fixed["bundle_manifest"], "a bundle manifest", manifest_now)
    if analysed < fixed["participants"]:
        found.append(f"{_participants(analysed)} analysed, fewer than the {fixed['participants']} planned")
    elif analysed > fixed["participants"]:
        found.append(f"{_participants(analysed)} analysed, more than the {fixed['participants']} planned")
    if _rules(rules) != fixed["exclusions"]:
        found.append(
            f"exclusions differ: {_rules_text({'exclusions': _rules(rules)})}; preregistered {_rules_text(fixed)}"
        )
    for key, name, now in (("foil", "Foil", foil_version()), ("model_version", "the report's model", MODEL_VERSION)):
        if fixed.get(key) is None:
            found.append(
                f"the preregistration does not record the version of {name}, so a change of it cannot be ruled "
                f"out (this report: {now or 'unknown'})"
            )
        elif fixed[key] != now:
            found.append(f"{name} is version {now or 'unknown'}, the preregistration fixed version {fixed[key]}")
    return found


def _preregistered_study(fixed: dict[str, Any], study_text: str) -> str:
    """The preregistered study file's hash, as a hash of bytes. Version 1 hashed the text with LF line ends:
    where that matches, the stored text is the preregistered file and its bytes' hash stands for it."""
    if fixed.get("version") == 1:
        lines = study_text.replace("\r\n", "\n").replace("\r", "\n")
        if sha256(lines.encode("utf-8")) == fixed["study_file"]:
            return sha256(study_text.encode("utf-8"))
    return str(fixed["study_file"])


def _served(starts: list[dict[str, Any]], key: str, preregistered: str, what: str, checked: str | None) -> list[str]:
    """Each run of server starts that served another file than the preregistered one, reverted ones too; the
    latest run is left out where it served the file checked above (`checked`), which is reported already."""
    found, last = [], 0
    for served, group in groupby(starts, key=lambda start: start[key]):
        run = list(group)
        first, last = last + 1, last + len(run)
        if served != preregistered and not (last == len(starts) and served == checked):
            which = f"the {_nth(first)} start" if first == last else f"starts {first} to {last}"
            later = ", later reverted" if starts[-1][key] == preregistered else ""
            found.append(
                f"the server was started {_times(len(starts))}; {which} ({run[0]['at']}) served {what} that "
                f"differs from the preregistered one ({served or 'not readable'}){later}"
            )
    return found


def _participants(n: int) -> str:
    return f"{n} participant{'' if n == 1 else 's'}"


def _times(n: int) -> str:
    return {1: "once", 2: "twice"}.get(n, f"{n} times")


def _nth(n: int) -> str:
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"
