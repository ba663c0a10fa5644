"""glmer.R, the mixed model `foil export` writes beside long.csv: it reads only columns the export has, and where R
runs it fits every part of a small study database (a ranking by its pairwise orderings, as the report) and prints
an estimate for every scheme."""

from __future__ import annotations

import math
import random
import re
import subprocess

import pandas as pd
import pytest

from app.analysis.export_csv import export_study
from tests.app.analysis.test_export import answer_of
from tests.support.analysis import SCHEMES, add_participant, label_of


def noisy_answers(seed: int):
    """Right with a probability that differs by scheme: 80% and 60% of pairwise clips, 60% and 30% of rankings (a
    wrong ranking is the true order reversed); the other questions as answer_of gives them."""
    rng = random.Random(seed)

    def answer(screen: dict) -> dict:
        answers = answer_of(screen)
        first = screen.get("scheme") == SCHEMES[0]
        if screen["kind"] == "pairwise":
            wrong = next(r["agent"] for r in screen["robots"] if r["agent"] != screen["better"])
            right = rng.random() < (0.8 if first else 0.6)
            answers["better"] = label_of(screen, screen["better"] if right else wrong)
        if screen["kind"] == "ranking":
            right = rng.random() < (0.6 if first else 0.3)
            order = screen["true_order"] if right else screen["true_order"][::-1]
            answers["ranking"] = [label_of(screen, agent) for agent in order]
        return answers

    return answer


@pytest.fixture
def exported(survey_db, paper_study, bundle_dir, tmp_path):
    """An export of twelve participants (three per condition) and one the rules exclude."""
    _, study = paper_study
    for n in range(12):
        add_participant(survey_db, study, bundle_dir, condition=n % 4, answer=noisy_answers(n), seed=n)
    add_participant(survey_db, study, bundle_dir, condition=0, answer=noisy_answers(99), status="returned")
    return export_study(survey_db, study, tmp_path / "export").out, study


def test_the_script_reads_only_columns_the_export_has(exported):
    out, study = exported
    script = (out / "glmer.R").read_text()
    long, people = pd.read_csv(out / "long.csv"), pd.read_csv(out / "participants.csv")
    used = set(re.findall(r"\b(long|d|people)\$(\w+)", script))
    assert {table for table, _ in used} == {"long", "d", "people"}
    for table, column in used:
        assert column in (people if table == "people" else long).columns, f"{table}${column}"
    for question_type in ("choose", "rank"):  # the rows each part fits
        assert f'"{question_type}"' in script and question_type in set(long.question_type)
    assert f"schemes <- c({', '.join(f'{s!r}'.replace(chr(39), chr(34)) for s in study.design.schemes)})" in script
    assert 'read.csv("long.csv"' in script and "Rscript glmer.R" in script and "conditional" in script
    assert set(people.excluded) == {0, 1}  # the script's filter has both to tell apart


def test_the_script_fits_every_part_in_r(exported):
    """R with lme4 comes with `make test` (the Makefile's `r` target)."""
    out, _ = exported
    run = subprocess.run(["Rscript", "glmer.R"], cwd=out, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    printed = run.stdout
    long = pd.read_csv(out / "long.csv")
    for part, question_type in (("pairwise", "choose"), ("ranking", "rank")):
        section = printed.split(f"== {part} part: ")[1].split("== ")[0]
        kept = long[(long.question_type == question_type) & (long.participant != "hand012")]  # the returned one
        clips = kept["clip"].map(lambda listed: ";".join(sorted(listed.split(";")))).nunique()  # a set, one clip
        if part == "pairwise":
            assert section.startswith(f"{len(kept)} answers, 12 participants, {clips} clips")
        else:  # each ranking of k robots as its k(k-1)/2 pairwise orderings, as the report models it
            pairs = sum(math.comb(len(truth.split(">")), 2) for truth in kept.truth)
            assert pairs > len(kept) and section.startswith(f"{pairs} pairwise orderings, 12 participants, {clips} ")
        assert "Random effects:" in section and "Fixed effects:" in section
        for scheme in SCHEMES:  # each scheme's accuracy with its interval
            assert re.search(rf"^  {re.escape(scheme)}: 0\.\d+ \(0\.\d+ to [01]\.\d+\)$", section, re.MULTILINE)
        assert re.search(rf"^  {re.escape(SCHEMES[1])} against {re.escape(SCHEMES[0])}: \d", section, re.MULTILINE)
