"""`foil report`: the paper's Table 1 and Figures 3-4 for any study, with intervals, tests and exclusions.

One streaming pass over the database tallies what the analysis needs (counts, not rows), so the report of a large
study costs no more memory than that of a small one. The outputs are report.html (self-contained: figures
inlined as SVG, styles inline), each figure as PNG and SVG, and every table as CSV. matplotlib draws the figures
and comes with the `figures` extra: without it the report has every table and test and says how to get them.
"""

from __future__ import annotations

import csv
import io
import sys
import textwrap
from collections import Counter, defaultdict
from dataclasses import dataclass, field, replace
from importlib.util import find_spec
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

from app.analysis.answer_table import ORDER_SEPARATOR, long_rows, participant_records
from app.analysis.design import GUESS, UPDATE_MEASURES, chance, tasks
from app.analysis.exclusions import REASONS, ExclusionRules, exclusion_flags, median_duration_s
from app.analysis.model import Answers, ModelResult, RatingResult, Ratings, fit_accuracy, fit_ratings
from app.analysis.prereg import deviations
from app.analysis.source import analysis_database, analysis_study_text, bundle_world, served_bundle
from app.analysis.statistics import TestResult, accuracy_difference, ordinal_difference, wilson_interval
from app.page_templates import page_templates
from app.store.database import Database
from app.survey.study import NO_DIFFERENCE, ScaleQuestion, Study
from app.visible import World

if TYPE_CHECKING:
    from matplotlib.figure import Figure

ALL = "all scenarios"
ORDERINGS = "orderings"  # a ranking part's pairwise orderings (`ReportData.model`)
TASKS = {  # each part's title, in the world's words (`Words.say`, `ReportData.task_titles`)
    "pairwise": "part one: pairwise (which {agent} is better)",
    "ranking": "part two: global ranking (all {agents} in the right order)",
}
FIGURES_EXTRA = "pip install 'foil[figures]'"
# The paper's Figure 4: orange for disagreement, blue for agreement, grey for the middle.
DISAGREE, NEUTRAL, AGREE = ("#e66101", "#fdb863"), "#d9d9d9", ("#92c5de", "#0571b0")


@dataclass
class Tally:
    correct: int = 0
    incorrect: int = 0

    @property
    def n(self) -> int:
        return self.correct + self.incorrect

    @property
    def accuracy(self) -> float | None:
        return self.correct / self.n if self.n else None

    @property
    def interval(self) -> tuple[float, float] | None:
        return wilson_interval(self.correct, self.n)


@dataclass
class Exclusions:
    """Participants in the database (`before`), analysed (`after`) and met by each rule; `flagged`: those any rule
    excludes, analysed anyway when `included` (`foil report --include-excluded`, a quick look at a pilot)."""

    before: int = 0
    after: int = 0
    per_reason: Counter[str] = field(default_factory=Counter)
    rule: str = ""
    flagged: int = 0
    included: bool = False
    bots: str = ""  # where bots are analysed: the rules skipped for them (`ExclusionRules.bots_note`)

    def reasons(self) -> str:
        """How many each rule met, as "pilot_or_bot: 3, skipped_viewing: 3"."""
        return ", ".join(f"{reason}: {self.per_reason[reason]}" for reason in REASONS if self.per_reason[reason])

    def lines(self) -> list[str]:
        """Each rule that excluded anyone, with its count and reason, and the rules skipped for bots: what
        `foil report` and `foil export` print below their counts."""
        said = [
            f"  excluded: {self.per_reason[reason]} {reason} ({text})"
            for reason, text in REASONS.items()
            if self.per_reason[reason]
        ]
        return said + ([f"  {self.bots}"] if self.bots else [])

    def notice(self) -> str:
        """What a reader must know before the numbers: that excluded participants are in them, or that every
        participant was excluded and how to see their answers anyway; empty otherwise."""
        if self.included and self.flagged:
            return (
                f"This report includes {self.flagged} of {self.before} participant{'s' * (self.before != 1)} whom "
                f"the exclusion rules leave out ({self.reasons()}), because it was asked for with "
                "--include-excluded: a quick look, not a result."
            )
        if self.before and not self.after:
            kinds = (
                "; --include pilot,bot applies the other rules to pilots and bots"
                if self.per_reason["pilot_or_bot"]
                else ""
            )
            return (
                f"All {self.before} participant{'s' * (self.before != 1)} were excluded ({self.reasons()}), so "
                "nothing is analysed. To look at their answers anyway (a pilot, or bots that answer sooner than a "
                "clip plays), run foil report with --include-excluded: the report then analyses every participant "
                f"and says so at its top{kinds}."
            )
        return ""


@dataclass
class ReportData:
    """What the report shows, computed from the database by `tally_study`."""

    study: Study
    exclusions: Exclusions
    accuracy: dict[tuple[str, str, str], Tally]  # (task, scope, scheme) -> tally; scope ALL or a scenario
    unscored_rankings: int  # rankings whose clips gave no strict true order
    ratings: dict[str, dict[str, Counter[int]]]  # scale question -> scheme -> point -> answers
    per_clip: dict[str, dict[str, Any]] = field(default_factory=dict)  # clip id -> scheme, scenario, agents, Tally
    audits: dict[str, dict[str, Any]] = field(default_factory=dict)  # clip id -> the manifest's audit, when known
    answers: dict[str, Answers] = field(default_factory=dict)  # task -> its scored answers, for the model
    rated: dict[str, Ratings] = field(default_factory=dict)  # scale question -> its ratings, for their model
    updates: dict[str, Answers] = field(default_factory=dict)  # UPDATE_MEASURES name -> its answers, 1 = counted
    prereg: list[str] | None = None  # how the data differ from the preregistration (empty: they match), if given
    world: World = field(default_factory=World)  # the world the clips show, in whose words the report speaks
    _models: dict[str, ModelResult] = field(default_factory=dict, repr=False)
    _ratings: dict[str, RatingResult] = field(default_factory=dict, repr=False)

    @property
    def schemes(self) -> list[str]:
        return list(self.study.design.schemes)

    def task_titles(self) -> dict[str, str]:
        """Each part's title in the world's words ("part one: pairwise (which agent is better)")."""
        return {task: self.world.words.say(title) for task, title in TASKS.items()}

    def scopes(self) -> list[str]:
        seen = {scope for _, scope, _ in self.accuracy}
        design = self.study.design
        named = [*design.scenarios, *(s for names in design.scheme_scenarios.values() for s in names)]
        return [ALL] + [s for s in dict.fromkeys(named) if s in seen]

    def model(self, task: str) -> ModelResult:
        """The report's model of the task's answers (app/analysis/model.py), fitted once. A ranking part's model
        is of its pairwise orderings: each ranking of k agents gives k(k-1)/2 of them, each right or wrong against
        a chance of one half, so a ranking with one pair swapped counts as mostly right (the whole order's
        accuracy stays in Table 1)."""
        if task not in self._models:
            empty = Answers((), (), (), (), (), ())
            found = self.answers.get(ORDERINGS if task == "ranking" else task, empty)
            self._models[task] = fit_accuracy(found, self.schemes, self.model_chance(task))
        return self._models[task]

    def update_model(self, measure: str) -> ModelResult:
        """A measure of a study of updates (UPDATE_MEASURES), modelled as accuracy is, against guessing."""
        if measure not in self._models:
            empty = Answers((), (), (), (), (), ())
            self._models[measure] = fit_accuracy(self.updates.get(measure, empty), self.schemes, GUESS)
        return self._models[measure]

    def model_chance(self, task: str) -> float:
        return 0.5 if task == "ranking" else chance(self.study, task)

    def rating_model(self, question: str, points: int) -> RatingResult:
        if question not in self._ratings:
            empty = Ratings((), (), (), ())
            self._ratings[question] = fit_ratings(self.rated.get(question, empty), self.schemes, points)
        return self._ratings[question]

    def tasks(self) -> list[str]:
        return tasks(self.study)

    def accuracy_test(self, task: str, scope: str) -> TestResult:
        return accuracy_difference(
            {s: (self.tally(task, scope, s).correct, self.tally(task, scope, s).incorrect) for s in self.schemes}
        )

    def tally(self, task: str, scope: str, scheme: str) -> Tally:
        return self.accuracy.get((task, scope, scheme), Tally())

    def rating_test(self, question: str) -> TestResult:
        return ordinal_difference(
            {scheme: sorted(self.ratings[question][scheme].elements()) for scheme in self.schemes}
        )

    def scale_questions(self) -> list[tuple[str, ScaleQuestion]]:
        asked = self.study.part_questions()  # not the closing screen's scales: they rate no scheme
        return [(name, q) for name, q in self.study.questions.items() if isinstance(q, ScaleQuestion) and name in asked]


def tally_study(
    db: Database, study: Study, rules: ExclusionRules | None = None, include_excluded: bool = False
) -> ReportData:
    """The report's counts; ``include_excluded`` analyses every participant, whichever rule excludes them."""
    rules = rules or ExclusionRules()
    median_s = median_duration_s(db, study.study.id)  # real participants' pace, whoever is analysed
    threshold = rules.threshold_s(median_s)
    exclusions = Exclusions(rule=rules.describe(median_s), included=include_excluded, bots=rules.bots_note)
    accuracy: dict[tuple[str, str, str], Tally] = defaultdict(Tally)
    ratings: dict[str, dict[str, Counter[int]]] = {
        name: {scheme: Counter() for scheme in study.design.schemes}
        for name, q in study.questions.items()
        if isinstance(q, ScaleQuestion)
    }
    unscored = 0
    per_clip: dict[str, dict[str, Any]] = {}
    columns: dict[str, dict[str, list[Any]]] = {
        task: {name: [] for name in ("participant", "clip", "scheme", "scenario", "pair", "correct")}
        for task in (*TASKS, ORDERINGS)
    }
    rated: dict[str, dict[str, list[Any]]] = {
        name: {column: [] for column in ("participant", "clip", "scheme", "value")} for name in ratings
    }
    updates: dict[str, dict[str, list[Any]]] = {
        measure: {name: [] for name in ("participant", "clip", "scheme", "scenario", "pair", "correct")}
        for measure in (UPDATE_MEASURES if study.design.updates else ())
    }
    for record in participant_records(db, study.study.id):
        flags = exclusion_flags(record.participant, threshold, record.responses, rules, record.plan)
        exclusions.before += 1
        exclusions.per_reason.update(reason for reason in REASONS if flags[reason])
        if flags["excluded"]:
            exclusions.flagged += 1
            if not include_excluded:
                continue
        exclusions.after += 1
        for row in long_rows(study, record):
            kind = row.get("question_type")
            if row.get("called") is not None:
                _tally_update(row, updates)
            if kind in ("choose", "rank") or (kind == "compare" and row.get("truth") not in (None, NO_DIFFERENCE)):
                if row["correct"] is None:
                    unscored += 1
                    continue
                task = "ranking" if kind == "rank" else "pairwise"
                pair = " vs ".join(sorted(row["agents"].split(";"))) if task == "pairwise" else ""
                if task == "pairwise" and row.get("clip"):
                    entry = per_clip.setdefault(
                        row["clip"],
                        {
                            "scheme": row["scheme"],
                            "scenario": row["scenario"],
                            "agents": pair,
                            "better": row["truth"],
                            "tally": Tally(),
                        },
                    )
                    entry["tally"].correct += row["correct"]
                    entry["tally"].incorrect += 1 - row["correct"]
                # a ranking's clips are listed in the order its participant saw them: the set is what was ranked
                clip = row["clip"] if task == "pairwise" else ";".join(sorted(str(row["clip"]).split(";")))
                for name, value in (
                    ("participant", row["participant"]),
                    ("clip", clip),
                    ("scheme", row["scheme"]),
                    ("scenario", row["scenario"]),
                    ("pair", pair),
                    ("correct", row["correct"]),
                ):
                    columns[task][name].append(value)
                for scope in (ALL, row["scenario"]):
                    tally = accuracy[(task, scope, row["scheme"])]
                    tally.correct += row["correct"]
                    tally.incorrect += 1 - row["correct"]
                if task == "ranking":
                    for right in orderings(row["answer_agent"], row["truth"]):
                        # the pair is no covariate: its k(k-1)/2 - 1 parameters would cost small studies their test
                        for name, value in zip(columns[ORDERINGS], (row["participant"], clip, row["scheme"],
                                               row["scenario"], "", right), strict=True):  # fmt: skip
                            columns[ORDERINGS][name].append(value)
            elif kind == "scale" and row["scheme"] in ratings[row["question"]]:
                ratings[row["question"]][row["scheme"]][row["value"]] += 1
                clip = ";".join(sorted(str(row["clip"]).split(";")))
                for name, value in zip(rated[row["question"]], (row["participant"], clip, row["scheme"], row["value"]),
                                       strict=True):  # fmt: skip
                    rated[row["question"]][name].append(value)
    return ReportData(
        study=study,
        exclusions=exclusions,
        accuracy=dict(accuracy),
        unscored_rankings=unscored,
        ratings=ratings,
        per_clip=dict(sorted(per_clip.items())),
        answers={task: Answers(**values) for task, values in columns.items()},
        rated={name: Ratings(**values) for name, values in rated.items()},
        updates={measure: Answers(**values) for measure, values in updates.items()},
    )


def _tally_update(row: dict[str, Any], updates: dict[str, dict[str, list[Any]]]) -> None:
    """A compare answer on an update pair, into each measure that reads its kind of update."""
    pair = " vs ".join(sorted(row["agents"].split(";")))
    for measure, (kinds, counted) in UPDATE_MEASURES.items():
        if row["update"] in kinds:
            hit = row["correct"] if counted == "right" else int(row["called"] == counted)
            for name, value in zip(updates[measure], (row["participant"], row["clip"], row["scheme"], row["scenario"],
                                   pair, hit), strict=True):  # fmt: skip
                updates[measure][name].append(value)


def orderings(answer: str, truth: str) -> list[int]:
    """A ranking's pairwise orderings: for each pair of agents, 1 when the answer puts them in the true order.
    Three agents give three; a ranking with one neighbouring pair swapped gets two of three."""
    given = answer.split(ORDER_SEPARATOR)
    true = truth.split(ORDER_SEPARATOR)
    return [int(given.index(better) < given.index(worse)) for i, better in enumerate(true) for worse in true[i + 1 :]]


def _audits(bundle_dir: str) -> dict[str, dict[str, Any]]:
    """Each clip's audit (what it visibly shows against the ground truth) from the bundle's manifest, with which
    label on screen is which agent (``labels``: "Agent 2 = hi, Agent 5 = lo"), since its words name labels."""
    from app.formats import Manifest

    manifest = Manifest.model_validate_json((Path(bundle_dir) / "manifest.json").read_text(encoding="utf-8"))
    return {
        clip.id: clip.audit.model_dump()
        | {"labels": ", ".join(f"{label} = {agent}" for agent, label in zip(clip.agents, clip.labels, strict=True))}
        for clip in manifest.clips
        if clip.audit is not None
    }


# Tables ------------------------------------------------------------------------------------------------------


def _number(value: float | None, digits: int = 4) -> str | float:
    return "" if value is None else round(value, digits)


def _significant(value: float | None, digits: int = 3) -> str | float:
    """A p-value to 3 significant digits."""
    return "" if value is None else float(f"{value:.{digits}g}")


def table1_rows(data: ReportData) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    for scope in data.scopes():
        for scheme in data.schemes:
            row: dict[str, Any] = {"scope": scope, "scheme": scheme}
            for task in TASKS:
                tally = data.tally(task, scope, scheme)
                low, high = tally.interval or (None, None)
                row |= {
                    f"{task}_correct": tally.correct,
                    f"{task}_incorrect": tally.incorrect,
                    f"{task}_n": tally.n,
                    f"{task}_accuracy": _number(tally.accuracy),
                    f"{task}_ci95_low": _number(low),
                    f"{task}_ci95_high": _number(high),
                }
            rows.append(row)
    return rows


def model_rows(data: ReportData) -> list[dict[str, Any]]:
    """Per part: what was fitted, on how many participants and clips, and the primary test that the schemes
    differ (a ranking part: of its pairwise orderings)."""
    rows = []
    for task in data.tasks():
        fit = data.model(task)
        rows.append(
            {
                "task": task,
                "answers": "pairwise orderings of each ranking" if task == "ranking" else "answers",
                "model": fit.formula,
                "participants": fit.participants,
                "clips": fit.clips,
                "df": _number(fit.df, 2) if fit.scheme_p is not None else "",
                "test": fit.scheme_test if fit.estimable else "",
                "p_value": _significant(fit.scheme_p),
                "note": fit.note,
            }
        )
    return rows


def model_accuracy_rows(data: ReportData) -> list[dict[str, Any]]:
    """Per part and scheme: the model's accuracy with its 95% interval, and the test against chance (secondary:
    Holm-adjusted over the part's schemes), or why there is none."""
    return [
        {
            "task": task,
            "scheme": e.scheme,
            "answers": e.n,
            "clips": e.clips,
            "accuracy": _number(e.accuracy),
            "ci95_low": _number(e.low),
            "ci95_high": _number(e.high),
            "chance": _number(data.model_chance(task)),
            "df": _number(e.df, 2),
            "p_vs_chance": _significant(e.p_chance),
            "p_holm": _significant(e.p_holm),
            "note": e.note,
        }
        for task in data.tasks()
        for e in data.model(task).schemes
    ]


def model_contrast_rows(data: ReportData) -> list[dict[str, Any]]:
    """Per part and pair of schemes: the difference in accuracy with its 95% interval and the p of the same test,
    Holm-adjusted unless it is the part's primary test, and the odds ratio with its own interval."""
    return [
        {
            "task": task,
            "scheme": c.scheme,
            "reference": c.reference,
            "difference": _number(c.difference),
            "ci95_low": _number(c.low),
            "ci95_high": _number(c.high),
            "odds_ratio": _number(c.odds_ratio),
            "or_ci95_low": _number(c.or_low),
            "or_ci95_high": _number(c.or_high),
            "or_p_value": _significant(c.or_p_value),
            "or_note": c.or_note,
            "test": c.test,
            "df": _number(c.df, 2),
            "p_value": _significant(c.p_value),
            "p_holm": _significant(c.p_holm),
            "primary": int(c.primary),
            "note": c.note,
        }
        for task in data.tasks()
        for c in data.model(task).contrasts
    ]


def pooled_test_rows(data: ReportData) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    for scope in data.scopes():
        for task in TASKS:
            result = data.accuracy_test(task, scope)
            rows.append(
                {
                    "scope": scope,
                    "task": task,
                    "test": result.test,
                    "statistic": _number(result.statistic),
                    "p_value": _significant(result.p_value),
                    "odds_ratio": _number(result.effect),
                }
            )
    return rows


def rating_rows(data: ReportData) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    for name, question in data.scale_questions():
        labels = question.point_labels()
        for scheme in data.schemes:
            counts = data.ratings[name][scheme]
            total = sum(counts.values())
            for point in range(1, question.points + 1):
                share = 100 * counts[point] / total if total else None
                rows.append(
                    {
                        "question": name,
                        "scheme": scheme,
                        "point": point,
                        "label": labels[point - 1],
                        "answers": counts[point],
                        "percent": _number(share, 2),
                    }
                )
    return rows


def rating_test_rows(data: ReportData) -> list[dict[str, Any]]:
    """Per rating question: the model's test that the schemes' mean ratings differ, or why there is none."""
    rows: list[dict[str, Any]] = []
    for name, question in data.scale_questions():
        fit = data.rating_model(name, question.points)
        counts = {f"n_{scheme}": sum(data.ratings[name][scheme].values()) for scheme in data.schemes}
        rows.append(
            {
                "question": name,
                "test": fit.test if fit.estimable else fit.note,
                "p_value": _significant(fit.p_value),
                **counts,
                "note": fit.note if fit.estimable else "",
            }
        )
    return rows


def rating_model_rows(data: ReportData) -> list[dict[str, Any]]:
    """Per rating question: each scheme's mean with its 95% interval, then each pairwise difference with its
    interval and p (Holm-adjusted over the question's pairs)."""
    rows: list[dict[str, Any]] = []
    for name, question in data.scale_questions():
        fit = data.rating_model(name, question.points)
        rows += [
            {"question": name, "scheme": m.scheme, "reference": "", "answers": m.n, "estimate": _number(m.mean),
             "ci95_low": _number(m.low), "ci95_high": _number(m.high), "p_value": "", "p_holm": "", "note": m.note}
            for m in fit.means
        ]  # fmt: skip
        rows += [
            {"question": name, "scheme": c.scheme, "reference": c.reference, "answers": "",
             "estimate": _number(c.difference), "ci95_low": _number(c.low), "ci95_high": _number(c.high),
             "p_value": _significant(c.p_value), "p_holm": _significant(c.p_holm), "note": c.note}
            for c in fit.contrasts
        ]  # fmt: skip
    return rows


def update_rows(data: ReportData) -> list[dict[str, Any]]:
    """A study of updates: per measure and scheme, its rate with the model's 95% interval and the test against
    guessing, or why there is none; then per measure the test that the schemes differ."""
    rows: list[dict[str, Any]] = []
    for measure, answers in data.updates.items():
        fit = data.update_model(measure)
        estimated = {e.scheme: e for e in fit.schemes}
        for scheme in data.schemes:
            counted = [hit for hit, s in zip(answers.correct, answers.scheme, strict=True) if s == scheme]
            e = estimated.get(scheme)
            rows.append(
                {
                    "measure": measure,
                    "scheme": scheme,
                    "answers": len(counted),
                    "clips": e.clips
                    if e
                    else len({c for c, s in zip(answers.clip, answers.scheme, strict=True) if s == scheme}),
                    "rate": _number(sum(counted) / len(counted) if counted else None),
                    "ci95_low": _number(e.low if e else None),
                    "ci95_high": _number(e.high if e else None),
                    "guessing": _number(GUESS),
                    "df": _number(e.df if e else None, 2),
                    "p_vs_guessing": _significant(e.p_chance if e else None),
                    "note": e.note if e else (fit.note or "not tested: no answers"),
                }
            )
        tested = fit.scheme_p is not None
        rows.append(
            {
                "measure": measure,
                "scheme": "schemes differ",
                "answers": len(answers.correct),
                "clips": fit.clips,
                "rate": "",
                "ci95_low": "",
                "ci95_high": "",
                "guessing": "",
                "df": _number(fit.df, 2) if tested else "",
                "p_vs_guessing": _significant(fit.scheme_p),
                "note": fit.scheme_test if fit.estimable else fit.note,
            }
        )
    return rows


def rank_test_rows(data: ReportData) -> list[dict[str, Any]]:
    """The appendix's rank tests of the ratings, which count every rating as independent."""
    rows: list[dict[str, Any]] = []
    for name, _ in data.scale_questions():
        result = data.rating_test(name)
        rows.append(
            {
                "question": name,
                "test": result.test,
                "statistic": _number(result.statistic),
                "p_value": _significant(result.p_value),
                "rank_biserial": _number(result.effect),
            }
        )
    return rows


def exclusion_rows(data: ReportData) -> list[dict[str, Any]]:
    e = data.exclusions
    rows = [{"rule": "participants in the database", "participants": e.before}]
    rows += [
        {
            "rule": f"excluded: {text}" + (f" ({e.rule})" if reason == "too_fast" else ""),
            "participants": e.per_reason[reason],
        }
        for reason, text in REASONS.items()
    ]
    analysed = "analysed (every participant: --include-excluded)" if e.included else "analysed (no rule applies)"
    rows.append({"rule": analysed + (f"; {e.bots}" if e.bots else ""), "participants": e.after})
    return rows


def per_clip_rows(data: ReportData) -> list[dict[str, Any]]:
    """Part one's accuracy per clip with the clip's audit, as report.html's table shows it."""
    rows = []
    for clip, entry in data.per_clip.items():
        tally, audit = entry["tally"], data.audits.get(clip, {})
        rows.append(
            {
                "clip": clip,
                "scheme": entry["scheme"],
                "scenario": entry["scenario"],
                "agents": entry["agents"],
                "better": entry["better"],
                "answers": tally.n,
                "correct": tally.correct,
                "accuracy": _number(tally.accuracy),
                "audit_shows": audit.get("shows", ""),
                "audit_why": audit.get("why", ""),
                "audit_labels": audit.get("labels", ""),
            }
        )
    return rows


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    with path.open("w", encoding="utf-8", newline="") as handle:
        if rows:
            writer = csv.DictWriter(handle, fieldnames=list(rows[0]), lineterminator="\r\n")
            writer.writeheader()
            writer.writerows(rows)


# Figures -----------------------------------------------------------------------------------------------------


def figures_installed() -> bool:
    """Whether matplotlib (the `figures` extra) is there to draw the report's figures."""
    return find_spec("matplotlib") is not None


def _pyplot() -> ModuleType:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({"svg.hashsalt": "foil", "svg.fonttype": "none", "font.size": 12})
    return plt


def distribution_figure(data: ReportData, name: str, question: ScaleQuestion) -> Figure:
    """The paper's Figure 3 for any scale question: the share of answers at each point, one bar per scheme."""
    plt = _pyplot()
    figure: Figure
    figure, axes = plt.subplots(figsize=(7.5, 4.2))
    labels = question.point_labels()
    width = 0.8 / max(1, len(data.schemes))
    any_answers = False
    for k, scheme in enumerate(data.schemes):
        counts = data.ratings[name][scheme]
        total = sum(counts.values())
        any_answers |= total > 0
        shares = [100 * counts[p] / total if total else 0 for p in range(1, question.points + 1)]
        positions = [p + (k - (len(data.schemes) - 1) / 2) * width for p in range(1, question.points + 1)]
        axes.bar(positions, shares, width=width, label=f"{scheme} (n = {total})")
    axes.set_xticks(
        range(1, question.points + 1),
        [f"{p}\n{label}" if not label.isdigit() else str(p) for p, label in enumerate(labels, 1)],
    )
    axes.set_ylabel("% of answers")
    axes.set_title(textwrap.fill(question.text, 60), fontsize=12)
    if any_answers:
        axes.legend(frameon=False)
    else:
        axes.text(0.5, 0.5, "no answers", transform=axes.transAxes, ha="center", va="center", color="grey")
    axes.spines[["top", "right"]].set_visible(False)
    figure.tight_layout()
    return figure


# Figures are 12-pt text and at most 12 inches wide, so shown at report.html's figure width (60rem, 960 px) no
# text is under 12 px (12 pt = 16 px at 9 inches; 13.3 px at 12 inches); likert panels wrap after two columns.
LIKERT_COLUMNS = 2


def _likert_colours(points: int) -> list[str]:
    """Disagreement (orange) below the middle, agreement (blue) above, grey in the middle of an odd scale."""
    half = points // 2
    low = [DISAGREE[0]] * (half - 1) + [DISAGREE[1]] if half else []
    high = [AGREE[0]] + [AGREE[1]] * (half - 1) if half else []
    return low[:half] + ([NEUTRAL] if points % 2 else []) + high[:half]


def likert_figure(data: ReportData, questions: list[tuple[str, ScaleQuestion]]) -> Figure:
    """The paper's Figure 4: per labelled question, one diverging stacked bar per scheme, centred on the middle
    of the scale (disagreement to the left, agreement to the right)."""
    plt = _pyplot()
    n = max(1, len(questions))
    columns = min(n, LIKERT_COLUMNS)
    rows = -(-n // columns)
    figure: Figure
    figure, axes_grid = plt.subplots(
        rows, columns, figsize=(6.0 * columns, (2.6 + 0.7 * len(data.schemes)) * rows), squeeze=False
    )
    axes_list = [axes for row in axes_grid for axes in row]
    for axes in axes_list[n:]:
        axes.set_visible(False)
    for axes, (name, question) in zip(axes_list, questions, strict=False):
        colours = _likert_colours(question.points)
        middle = question.points / 2 + 0.5  # the neutral point (odd scales) or the gap between the halves
        ticks = []
        for row, scheme in enumerate(data.schemes):
            counts = data.ratings[name][scheme]
            total = sum(counts.values())
            ticks.append(f"{scheme}\n(n = {total})")
            shares = [100 * counts[p] / total if total else 0 for p in range(1, question.points + 1)]
            left = -sum(s for p, s in enumerate(shares, 1) if p < middle) - (
                shares[int(middle) - 1] / 2 if middle == int(middle) else 0
            )
            for p, share in enumerate(shares, 1):
                axes.barh(
                    row,
                    share,
                    left=left,
                    color=colours[p - 1],
                    edgecolor="white",
                    label=question.point_labels()[p - 1] if row == 0 else None,
                )
                left += share
        axes.axvline(0, color="black", linewidth=0.6)
        axes.set_yticks(range(len(data.schemes)), ticks)
        axes.set_xlim(-100, 100)
        axes.set_xlabel("% of answers (disagreement left, agreement right)")
        axes.set_title(textwrap.fill(question.text, 45), fontsize=12)
        axes.invert_yaxis()
        axes.spines[["top", "right", "left"]].set_visible(False)
    handles, labels = axes_list[0].get_legend_handles_labels()
    if handles:
        figure.legend(handles, labels, loc="lower center", ncol=min(len(labels), 3), frameon=False, fontsize=12)
    figure.tight_layout(rect=(0, 0.22 / rows, 1, 1))
    return figure


def _save(figure: Figure, out: Path, stem: str) -> str:
    """Write PNG and SVG; return the SVG text for inlining in report.html."""
    figure.savefig(out / f"{stem}.png", dpi=150, metadata={"Software": None})
    buffer = io.StringIO()
    figure.savefig(buffer, format="svg", metadata={"Date": None, "Creator": None})
    figure.savefig(out / f"{stem}.svg", metadata={"Date": None, "Creator": None})
    import matplotlib.pyplot as plt

    plt.close(figure)
    svg = buffer.getvalue()
    return svg[svg.index("<svg") :]


# The report --------------------------------------------------------------------------------------------------


def render_report(data: ReportData, out: Path | None = None) -> str:
    """report.html as text; with `out`, also write it there with the figures (PNG, SVG) and tables (CSV)."""
    import tempfile

    with tempfile.TemporaryDirectory() as scratch:
        folder = out or Path(scratch)
        folder.mkdir(parents=True, exist_ok=True)
        scales = data.scale_questions()
        labelled = [(name, q) for name, q in scales if q.labels is not None]
        drawn = figures_installed()
        figures: list[tuple[str, str, str | None, str]] = [
            (
                f"distribution-{name}",
                f"Answers to “{q.text}” per scheme",
                name,
                _save(distribution_figure(data, name, q), folder, f"distribution-{name}"),
            )
            for name, q in scales
            if q.labels is None and drawn
        ]
        if labelled and drawn:
            figures.append(
                (
                    "likert",
                    "Agreement per scheme (diverging stacked bars)",
                    None,
                    _save(likert_figure(data, labelled), folder, "likert"),
                )
            )
        tables = {
            "table1.csv": table1_rows(data),
            "model.csv": model_rows(data),
            "model_accuracy.csv": model_accuracy_rows(data),
            "model_contrasts.csv": model_contrast_rows(data),
            "pooled_tests.csv": pooled_test_rows(data),
            "ratings.csv": rating_rows(data),
            "rating_tests.csv": rating_test_rows(data),
            "rating_model.csv": rating_model_rows(data),
            "rating_rank_tests.csv": rank_test_rows(data),
            "exclusions.csv": exclusion_rows(data),
            "per_clip.csv": per_clip_rows(data),
        }
        if data.updates:  # a study of updates only: the others' reports stay as they were
            tables["updates.csv"] = update_rows(data)
        if out is not None:
            for name, rows in tables.items():
                _write_csv(folder / name, rows)
        html = (
            page_templates()
            .get_template("report.html")
            .render(
                data=data,
                tasks=data.task_titles(),
                all_scopes=ALL,
                figures=figures,
                exclusion_rows=tables["exclusions.csv"],
                rank_tests=tables["rating_rank_tests.csv"],
                tables=list(tables) if out is not None else [],
                files=out is not None,
                likert=bool(labelled),
                figures_left_out=bool(scales) and not drawn,
                figures_extra=FIGURES_EXTRA,
                chance={task: data.model_chance(task) for task in data.tasks()},
                prereg=data.prereg,
                updates=tables.get("updates.csv", []),
            )
        )
        if out is not None:
            (folder / "report.html").write_text(html, encoding="utf-8")
    return html


def _preregistration(path: str) -> dict[str, Any]:
    """prereg.json as `foil prereg` wrote it, or a clear error."""
    import json

    from app.analysis.prereg import VERSION

    file = Path(path)
    if file.is_dir():
        file = file / "prereg.json"
    try:
        fixed: dict[str, Any] = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise ValueError(f"--prereg {path}: not a prereg.json written by foil prereg ({error})") from None
    if not isinstance(fixed, dict) or fixed.get("version") not in range(1, VERSION + 1):
        raise ValueError(
            f"--prereg {path}: not a prereg.json written by foil prereg (version 1 to {VERSION}; "
            f"a newer one needs a newer Foil)"
        )
    return fixed


def run_report(
    *,
    database_url: str,
    study: str | None,
    out: str,
    rules: ExclusionRules,
    bundle: str | None = None,
    prereg: str | None = None,
    include_excluded: bool = False,
) -> int:
    """`foil report`: prints Table 1 in short and where the report went. The per-clip table shows each clip's
    audit from the manifest of ``bundle``, by default the bundle the server last served the study from;
    ``include_excluded`` analyses every participant, and the report and what it prints say so."""
    if bundle and not (Path(bundle) / "manifest.json").is_file():
        raise ValueError(f"no manifest.json in bundle {bundle}: give the bundle the study was served from")
    fixed = _preregistration(prereg) if prereg else None
    db = analysis_database(database_url)
    try:
        source = analysis_study_text(db, study)
        data = tally_study(db, source.study, rules, include_excluded)
        bundle = bundle or served_bundle(db, data.study.study.id)
    finally:
        db.dispose()
    if fixed is not None:
        manifest = Path(bundle) / "manifest.json" if bundle else None
        found = deviations(fixed, source.text, manifest, data.exclusions.after, rules, source.starts)
        if include_excluded:
            found.append("excluded participants are analysed (--include-excluded)")
        data = replace(data, prereg=[source.differs, *found] if source.differs else found)
    elif source.differs:
        print(f"warning: {source.differs}", file=sys.stderr)
    data = replace(data, world=bundle_world(bundle))
    if bundle is not None and (Path(bundle) / "manifest.json").is_file():
        data = replace(data, audits=_audits(bundle))
    else:
        print(
            f"warning: the bundle the study was served from {'is not known' if bundle is None else 'is gone: '}"
            f"{bundle or ''}; give it with --bundle (or FOIL_BUNDLE_DIR) to fill the per-clip audit column",
            file=sys.stderr,
        )
    render_report(data, Path(out))
    if data.scale_questions() and not figures_installed():
        print(f"warning: the report has no figures: they need matplotlib: {FIGURES_EXTRA}", file=sys.stderr)
    e = data.exclusions
    print(f"{e.before} participant{'s' * (e.before != 1)}, {e.after} analysed after exclusions")
    for line in e.lines():
        print(line)
    if e.notice():
        print(e.notice())
    for row in table1_rows(data):
        if row["scope"] == ALL:
            print(
                f"{row['scheme']}: pairwise {row['pairwise_correct']}/{row['pairwise_n']}, "
                f"ranking {row['ranking_correct']}/{row['ranking_n']}"
            )
    for task in data.tasks():
        fit = data.model(task)
        tested = f"{fit.scheme_test}, p = {fit.scheme_p:.3g}" if fit.scheme_p is not None else fit.scheme_test
        print(f"{task} model: " + (tested if fit.estimable else fit.note))
    for row in update_rows(data):
        if row["scheme"] != "schemes differ":
            interval = f" (95% interval {row['ci95_low']} to {row['ci95_high']})" if row["ci95_low"] != "" else ""
            print(
                f"{row['measure']}, {row['scheme']}: {row['rate']} of {row['answers']}{interval}"
                + (f"; {row['note']}" if row["note"] else "")
            )
    if data.prereg:
        n = len(data.prereg)
        print(f"{n} deviation{'s' * (n != 1)} from the preregistration: " + "; ".join(data.prereg))
    print(f"report: {Path(out) / 'report.html'}")
    return 0
