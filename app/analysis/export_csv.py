"""`foil export`: long.csv (one row per answer), wide.csv (one row per participant), participants.csv and the
codebook (codebook.md for people, codebook.json for code), written in one streaming pass over the database, and
glmer.R, which fits the field's mixed model to long.csv in R.

Every file is plain UTF-8 CSV with a header that pandas, R and spreadsheets read without options. Text that a
spreadsheet would run as a formula is neutralised (see `neutralise`).
"""

from __future__ import annotations

import csv
import io
import json
import re
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, TextIO

from app.analysis.answer_table import (
    LIST_SEPARATOR,
    ORDER_SEPARATOR,
    PARTICIPANT_COLUMNS,
    Column,
    WideLayout,
    long_columns,
    long_rows,
    participant_records,
    participant_row,
)
from app.analysis.exclusions import REASONS, ExclusionRules, exclusion_flags, median_duration_s
from app.analysis.source import analysis_database, analysis_study, bundle_world, served_bundle
from app.store.database import Database
from app.survey.assignment import conditions
from app.survey.study import FEEDBACK, ChoiceQuestion, ScaleQuestion, Study
from app.visible import Words

# Whole cells that pandas (by default) or R read as a missing value, though a participant may type them.
MISSING_TOKENS = {
    "#N/A",
    "#N/A N/A",
    "#NA",
    "-1.#IND",
    "-1.#QNAN",
    "-NaN",
    "-nan",
    "1.#IND",
    "1.#QNAN",
    "<NA>",
    "N/A",
    "NA",
    "NULL",
    "NaN",
    "None",
    "n/a",
    "nan",
    "null",
}
FILES = ("long.csv", "wide.csv", "participants.csv")

# What a spreadsheet may take for the start of a formula: = + - @, their fullwidth and small forms (which some
# spreadsheets and input methods turn into the ASCII ones) and the minus sign.
FORMULA_SIGNS = "=+\\-@\uff1d\uff0b\uff0d\uff20\ufe66\ufe62\ufe63\ufe6b\u2212"
# A spreadsheet that splits a cell on a comma, semicolon, tab or line break, and trims whitespace, reads a formula
# from any piece. A piece starts at the cell's start or right after one of these; an apostrophe put there makes
# the piece text however it is split and trimmed. A piece that starts with an apostrophe gets one too, so that
# every apostrophe at a piece start in the export is one that was put there.
_NEEDS_MARK = re.compile(rf"(^|[,;\t\n\r])(?=[^\S\t\n\r]*[{FORMULA_SIGNS}]|')")
_MARK = re.compile(r"(^|[,;\t\n\r])'")
_RISKY = re.compile(rf"[{FORMULA_SIGNS}'\x00\u2400]")
# NUL, which no spreadsheet or PostgreSQL text column keeps, is written as U+2400 (the symbol for null) and a 0;
# a U+2400 that was typed is doubled.
NUL_SIGN = "\u2400"
_NUL_ESCAPE = re.compile(f"{NUL_SIGN}([{NUL_SIGN}0])")


def neutralise(text: str) -> str:
    """Text as written to a CSV cell, safe in any spreadsheet and reversible with `restore`: an apostrophe at the
    start of every piece of the cell (see `_NEEDS_MARK`) that starts, after any whitespace, with a formula sign
    or with an apostrophe; at the start of a cell that starts with a tab or line break or reads as a missing
    value; NUL escaped."""
    if _RISKY.search(text) is None and text[:1] not in ("\t", "\n", "\r") and text not in MISSING_TOKENS:
        return text  # the common case: nothing to do
    if "\x00" in text or NUL_SIGN in text:
        text = text.replace(NUL_SIGN, NUL_SIGN * 2).replace("\x00", NUL_SIGN + "0")
    marked = _NEEDS_MARK.sub(r"\1'", text)
    if not marked.startswith("'") and (text[:1] in ("\t", "\n", "\r") or text in MISSING_TOKENS):
        marked = "'" + marked
    return marked


def restore(cell: str) -> str:
    """What was typed, from a cell `neutralise` wrote: drop the apostrophe at the start of the cell and right after
    each comma, semicolon, tab or line break, then turn U+2400 followed by 0 back into NUL and a doubled U+2400
    into one."""
    text = _MARK.sub(r"\1", cell)
    if NUL_SIGN in text:
        text = _NUL_ESCAPE.sub(lambda m: "\x00" if m[1] == "0" else NUL_SIGN, text)
    return text


def _cell(value: object) -> str | int | float:
    if value.__class__ is str:  # the common case first: this runs for every cell
        return neutralise(value)
    if value is None:
        return ""
    if isinstance(value, int | float):
        return int(value) if isinstance(value, bool) else value
    return neutralise(str(value))


class _Table:
    """One CSV table being written to a text handle, its header first."""

    def __init__(self, handle: TextIO, columns: list[Column]) -> None:
        self.names = [c.name for c in columns]
        self.handle = handle
        self.writer = csv.writer(self.handle, lineterminator="\r\n")  # RFC 4180; quotes any CR or LF in text
        self.writer.writerow(self.names)
        self.rows = 0

    def write(self, row: dict[str, Any]) -> None:
        self.writer.writerow([_cell(row.get(name)) for name in self.names])
        self.rows += 1

    def close(self) -> None:
        self.handle.close()


def long_csv_chunks(db: Database, study: Study) -> Iterator[str]:
    """long.csv as text, one participant at a time, for a download that starts at once and streams."""
    buffer = io.StringIO()
    table = _Table(buffer, long_columns(study))
    for record in participant_records(db, study.study.id):
        for row in long_rows(study, record):
            table.write(row)
        yield buffer.getvalue()
        buffer.seek(0)
        buffer.truncate()
    yield buffer.getvalue()  # the header alone when there is nobody yet


@dataclass(frozen=True)
class ExportResult:
    out: Path
    participants: int
    answers: int  # rows of long.csv
    excluded: int
    seconds: float
    per_reason: Counter[str] = field(default_factory=Counter)  # participants each exclusion rule met
    bots: str = ""  # where bots are analysed: the rules skipped for them

    def lines(self) -> list[str]:
        """Each rule that excluded anyone, with its count and reason, and the rules skipped for bots."""
        said = [
            f"  excluded: {self.per_reason[reason]} {reason} ({text})"
            for reason, text in REASONS.items()
            if self.per_reason[reason]
        ]
        return said + ([f"  {self.bots}"] if self.bots else [])


def _question_codes(study: Study) -> dict[str, dict[str, Any]]:
    codes: dict[str, dict[str, Any]] = {}
    for name, question in study.questions.items():
        entry: dict[str, Any] = {"type": question.type, "text": question.text}
        if isinstance(question, ScaleQuestion):
            entry["points"] = question.points
            entry["point_labels"] = question.point_labels()
        if isinstance(question, ChoiceQuestion):
            entry["options"] = list(question.options)
        codes[name] = entry
    closing = study.closing
    if closing is not None:
        if closing.feedback:
            codes[FEEDBACK] = {"type": "text", "text": closing.feedback}
        for name in closing.asks():
            codes[name] |= {"asked": "closing", "required": name in closing.required}
    return codes


# How `foil report` models accuracy (app/analysis/model.py), so that an analyst can reproduce it from long.csv.
MODEL_TEXT = (
    "foil report models each part's answers (long.csv rows with question_type choose or rank; correct is the "
    "outcome; a ranking part by its pairwise orderings: each ranking of k {agents} gives k(k-1)/2 pairs, right when "
    "answer_agent puts them in the order of truth) as a logistic regression correct ~ scheme, with the pair of "
    "agents and the scenario as fixed effects where a pairwise part has more than one, fitted with Firth's penalty; "
    "its cluster-robust standard errors (CR2) are clustered by participant, by clip and by both (a ranking's clip "
    "is its ranked clips together), each test reading the largest of the three, with t tests on Satterthwaite "
    "degrees of freedom and the approximate Hotelling T-squared test for the schemes together, as R's clubSandwich "
    "computes them. It stands in for the mixed model with crossed random effects for participant and clip, in R: "
    "glmer(correct ~ scheme + (1 | participant) + (1 | clip), family = binomial), and gives population-averaged "
    "estimates with reliable p-values when a study has few clips per scheme; docs/analysis.md explains it. glmer.R "
    "in the export folder fits that mixed model (Rscript glmer.R)"
)

# glmer.R: the conditional mixed model per part in R, for analysts who want the field's usual model beside the
# report's. @NAME@ placeholders, since R code is full of braces.
GLMER_SCRIPT = r"""# glmer.R: the logistic mixed model of accuracy for study @STUDY@, written by foil export.
#
# Run it in the export folder: Rscript glmer.R  (needs R and the lme4 package: install.packages("lme4")).
#
# For each part (pairwise: the choose answers of long.csv; ranking: the rank answers, each ranking as its pairwise
# orderings, as the report models them: k(k-1)/2 pairs of k @AGENTS@, right when in the true order) it fits
#   glmer(correct ~ scheme + (1 | participant) + (1 | clip), family = binomial)
# to the participants the export's rules keep (excluded = 0 in participants.csv) and prints the fit's summary,
# each scheme's accuracy for a typical participant on a typical clip, and the odds ratio of every pair of schemes,
# with 95% Wald intervals. The first scheme of the study file is the reference level.
#
# These are conditional (subject-specific) odds ratios: the schemes compared for one participant on one clip.
# Foil's report gives population-averaged ones (over all participants and clips), which are smaller in log terms:
# averaging over participants' and clips' spread pulls a log odds ratio towards 0, by a factor of about
# sqrt(1 + 0.35 * (participant variance + clip variance)) (Zeger, Liang and Albert 1988). Compare the two on the
# same scale only. The report also adjusts for pair and scenario, which here the clips' effects take up, and a
# Wald interval from a handful of clips per scheme is too narrow (docs/analysis.md, "The model").

suppressPackageStartupMessages(library(lme4))

schemes <- c(@SCHEMES@)
long <- read.csv("long.csv", encoding = "UTF-8")
people <- read.csv("participants.csv", encoding = "UTF-8")
kept <- people$participant[people$excluded == 0]
z <- qnorm(0.975)

# 1 for each pair of agents that the answer puts in the true order (both best first, "@ORDER@"-separated)
orderings <- function(answer, truth) {
  given <- strsplit(answer, "@ORDER@", fixed = TRUE)[[1]]
  true <- strsplit(truth, "@ORDER@", fixed = TRUE)[[1]]
  pairs <- combn(length(true), 2)
  as.integer(match(true[pairs[1, ]], given) < match(true[pairs[2, ]], given))
}

for (part in c("pairwise", "ranking")) {
  type <- if (part == "pairwise") "choose" else "rank"
  d <- long[long$question_type == type & !is.na(long$correct) & long$participant %in% kept, ]
  if (nrow(d) == 0) next
  # a ranking's clips are listed in the order shown: sorted, one ranked set is one clip
  sets <- strsplit(d$clip, "@SEPARATOR@", fixed = TRUE)
  d$clip <- vapply(sets, function(clips) paste(sort(clips), collapse = "@SEPARATOR@"), "")
  if (part == "ranking") {
    right <- lapply(seq_len(nrow(d)), function(i) orderings(d$answer_agent[i], d$truth[i]))
    d <- d[rep(seq_len(nrow(d)), lengths(right)), ]
    d$correct <- unlist(right)
  }
  d$scheme <- droplevels(factor(d$scheme, levels = schemes))
  outcomes <- if (part == "ranking") "pairwise orderings" else "answers"
  cat(sprintf("\n== %s part: %d %s, %d participants, %d clips\n", part, nrow(d), outcomes,
              length(unique(d$participant)), length(unique(d$clip))))
  if (nlevels(d$scheme) < 2) {
    cat("fewer than two schemes answered: nothing to compare\n")
    next
  }
  fit <- tryCatch(glmer(correct ~ scheme + (1 | participant) + (1 | clip), family = binomial, data = d),
                  error = function(e) {
                    cat("glmer failed:", conditionMessage(e), "\n")
                    NULL
                  })
  if (is.null(fit)) next
  print(summary(fit))
  b <- fixef(fit)
  v <- as.matrix(vcov(fit))
  wald <- function(l) {
    estimate <- sum(l * b)
    se <- sqrt(drop(t(l) %*% v %*% l))
    c(estimate, estimate - z * se, estimate + z * se)
  }
  names <- levels(d$scheme)
  x <- model.matrix(~scheme, data.frame(scheme = factor(names, levels = names)))
  cat("\nAccuracy for a typical participant and clip (random effects 0), 95% Wald interval:\n")
  for (i in seq_along(names)) {
    r <- plogis(wald(x[i, ]))
    cat(sprintf("  %s: %.3f (%.3f to %.3f)\n", names[i], r[1], r[2], r[3]))
  }
  cat("\nConditional odds ratios, 95% Wald interval:\n")
  for (i in seq_along(names)) for (j in seq_along(names)) if (i < j) {
    r <- exp(wald(x[j, ] - x[i, ]))
    cat(sprintf("  %s against %s: %.2f (%.2f to %.2f)\n", names[j], names[i], r[1], r[2], r[3]))
  }
}
"""


def glmer_script(study: Study, words: Words | None = None) -> str:
    """glmer.R for this study: its schemes in the study file's order, so the reference level is the report's; its
    agents in the words of the world its clips show (``words``)."""
    return (
        GLMER_SCRIPT.replace("@STUDY@", study.study.id)
        .replace("@AGENTS@", (words or Words()).many())
        .replace("@SCHEMES@", ", ".join(json.dumps(s) for s in study.design.schemes))
        .replace("@SEPARATOR@", LIST_SEPARATOR)
        .replace("@ORDER@", ORDER_SEPARATOR)
    )


def codebook(
    study: Study, layout: WideLayout, rules: ExclusionRules, median_s: float | None, words: Words | None = None
) -> dict[str, Any]:
    """Everything an analyst needs to read the files: columns with their types, questions with their scales,
    conditions, exclusion rules, and the arguments that make pandas read each file with exact types; its texts
    speak of the agents in ``words``, those of the world the study's clips show."""
    say = (words or Words()).say
    files = {"long.csv": long_columns(study), "wide.csv": layout.columns, "participants.csv": PARTICIPANT_COLUMNS}
    return {
        "format": "foil.export/1",
        "study": {
            "id": study.study.id,
            "title": study.study.title,
            "schemes": list(study.design.schemes),
            "scheme_factor": study.design.scheme_factor,
            "scenarios": list(study.design.scenarios),
        },
        "files": {
            name: {
                "columns": [asdict(c) | {"description": say(c.description)} for c in columns],
                "read_csv": {
                    "dtype": {c.name: c.dtype for c in columns if c.dtype != "datetime"},
                    "parse_dates": [c.name for c in columns if c.dtype == "datetime"],
                },
            }
            for name, columns in files.items()
        },
        "questions": _question_codes(study),
        "conditions": [
            {
                "number": c.index + 1,
                "schemes": list(c.schemes),
                "part_scenarios": [study.part_scenario(p, c.rotation) for p in range(len(study.parts))],
            }
            for c in conditions(study)
        ],
        "exclusion_rules": {
            "reasons": REASONS,
            "too_fast": rules.describe(median_s),
            "analysed_kinds": list(rules.kinds),
            "too_fast_threshold_s": rules.threshold_s(median_s),
            "median_duration_s": median_s,
        }
        | ({"bots": rules.bots_note} if rules.bots_note else {}),
        "model": say(MODEL_TEXT),
        "neutralised_cells": "no piece of a cell can start a formula in a spreadsheet, however it splits cells (on a "
        "comma, semicolon, tab or line break) or trims spaces: an apostrophe is put at the "
        "start of the cell and right after each of those characters where the text then "
        "starts, after any spaces, with = + - @ (or their fullwidth forms, or the minus sign) or "
        "with an apostrophe; also in front of a cell that starts with a tab or line break or "
        "reads as a missing value (NA, null, None, ...). A NUL character is written as U+2400 "
        "followed by 0, and a typed U+2400 is doubled. To restore the text as typed: remove the "
        "apostrophe at the start of the cell and right after each comma, semicolon, tab or "
        'line break (pandas: series.str.replace(r"(^|[,;\\t\\n\\r])\'", r"\\1", '
        "regex=True)), then replace U+2400 0 by NUL and U+2400 U+2400 by U+2400 "
        "(app.analysis.export_csv.restore does both)",
    }


def codebook_markdown(book: dict[str, Any]) -> str:
    study = book["study"]
    lines = [
        f"# Codebook: study `{study['id']}`",
        "",
        study["title"],
        "",
        f"Schemes: {', '.join(study['schemes'])} ({study['scheme_factor']}-subjects). "
        f"Scenarios: {', '.join(study['scenarios'])}.",
        "",
        "All files are UTF-8 CSV with a header row; times are ISO 8601 in UTC; empty cells are missing values. "
        "`pd.read_csv(path)` reads them; for exact types pass "
        "`**codebook['files'][name]['read_csv']` from codebook.json.",
        "",
        f"Spreadsheet safety: {book['neutralised_cells']}.",
        "",
    ]
    for name, spec in book["files"].items():
        lines += [f"## {name}", "", "| column | type | meaning |", "|---|---|---|"]
        lines += [f"| `{c['name']}` | {c['dtype']} | {c['description']} |" for c in spec["columns"]]
        lines.append("")
    lines += ["## Questions", "", "| question | type | text | points, options, where asked |", "|---|---|---|---|"]
    for name, q in book["questions"].items():
        points = "; ".join(f"{i} = {label}" for i, label in enumerate(q.get("point_labels", []), start=1))
        if q.get("options"):
            points = "options: " + "; ".join(q["options"])
        if q.get("asked") == "closing":
            points = "; ".join(
                filter(None, [points, "closing screen, " + ("required" if q["required"] else "optional")])
            )
        lines.append(f"| `{name}` | {q['type']} | {q['text']} | {points} |")
    lines += ["", "## Conditions", "", "| condition | schemes in order | scenario of each part |", "|---|---|---|"]
    lines += [
        f"| {c['number']} | {', '.join(c['schemes'])} | {', '.join(c['part_scenarios'])} |" for c in book["conditions"]
    ]
    rules = book["exclusion_rules"]
    lines += ["", "## Model", "", book["model"] + ".", "", "## Exclusion flags", ""]
    lines += [f"- `{reason}`: {text}" for reason, text in rules["reasons"].items()]
    lines += [
        f"- time threshold of this export: {rules['too_fast']}",
        f"- participant kinds analysed (the others are flagged `pilot_or_bot`): "
        f"{', '.join(rules.get('analysed_kinds', ['real']))}",
        *(
            [f"- {rules['bots']} (a rehearsal of the analysis: they answer as fast as the pilot link lets them)"]
            if rules.get("bots")
            else []
        ),
        "",
    ]
    return "\n".join(lines)


def export_study(
    db: Database,
    study: Study,
    out: str | Path,
    rules: ExclusionRules | None = None,
    batch: int = 500,
    words: Words | None = None,
) -> ExportResult:
    """Write the three CSV files, the codebook and glmer.R into `out`, reading `batch` participants at a time; the
    codebook and glmer.R speak of the agents in ``words`` (the world's the clips show; by default, agents)."""
    started = time.perf_counter()
    rules = rules or ExclusionRules()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    layout = WideLayout(study)
    median_s = median_duration_s(db, study.study.id)  # real participants' pace, whoever is analysed
    threshold = rules.threshold_s(median_s)
    columns = {"long.csv": long_columns(study), "wide.csv": layout.columns, "participants.csv": PARTICIPANT_COLUMNS}
    tables = {
        name: _Table((out / name).open("w", encoding="utf-8", newline=""), cols) for name, cols in columns.items()
    }
    excluded = 0
    per_reason: Counter[str] = Counter()
    study_conditions = conditions(study)
    try:
        for record in participant_records(db, study.study.id, batch=batch):
            flags = exclusion_flags(record.participant, threshold, record.responses, rules, record.plan)
            excluded += flags["excluded"]
            per_reason.update(reason for reason in REASONS if flags[reason])
            long = list(long_rows(study, record))
            for row in long:
                tables["long.csv"].write(row)
            tables["wide.csv"].write(layout.row(record, long, flags))
            tables["participants.csv"].write(participant_row(record, flags, study_conditions))
    finally:
        for table in tables.values():
            table.close()
    book = codebook(study, layout, rules, median_s, words)
    (out / "codebook.json").write_text(json.dumps(book, indent=1) + "\n", encoding="utf-8")
    (out / "codebook.md").write_text(codebook_markdown(book), encoding="utf-8")
    (out / "glmer.R").write_text(glmer_script(study, words), encoding="utf-8")
    return ExportResult(
        out=out,
        participants=tables["participants.csv"].rows,
        answers=tables["long.csv"].rows,
        excluded=excluded,
        seconds=time.perf_counter() - started,
        per_reason=per_reason,
        bots=rules.bots_note,
    )


def run_export(
    *, database_url: str, study: str | None, out: str, rules: ExclusionRules, bundle: str | None = None
) -> int:
    """`foil export`: prints what was written, and each exclusion rule's count and reason. The codebook names the
    agents in the words of the world of ``bundle``, by default the bundle the server last served the study from."""
    db = analysis_database(database_url)
    try:
        read = analysis_study(db, study)
        world = bundle_world(bundle or served_bundle(db, read.study.id))
        result = export_study(db, read, out, rules, words=world.words)
    finally:
        db.dispose()
    print(
        f"{result.participants} participant{'' if result.participants == 1 else 's'} ({result.excluded} excluded by "
        f"the rules), {result.answers} answer row{'' if result.answers == 1 else 's'} in {result.seconds:.1f} s: "
        f"{', '.join(FILES)}, codebook.md, codebook.json, glmer.R in {result.out}"
    )
    for line in result.lines():
        print(line)
    return 0
