"""What a study's design means for every analysis of it: the tasks its parts pose and what guessing scores in each.
The report, the preregistration and the power simulation all read these, so they live below all three."""

from __future__ import annotations

import math

from app.survey.study import NO_DIFFERENCE, Study

# A study of updates (`[design] updates`): per measure, the updates whose answers it reads (what the ground truth
# says of each: better, worse, equal) and the answer it counts (`called`: later, earlier or no difference, or
# `right`: the answer names the better version). Each is modelled as accuracy is, against guessing one of three.
UPDATE_MEASURES = {
    "right on decided updates": (("better", "worse"), "right"),
    "no difference on equal pairs": (("equal",), NO_DIFFERENCE),
    "later called better on equal and worse updates": (("equal", "worse"), "later"),
}
GUESS = 1 / 3  # one of a compare question's three answers


def chance(study: Study, task: str) -> float:
    """The accuracy of guessing: one of two agents (one of three answers where a pairwise part asks a compare
    question: either agent or no difference), or one of the k! orders of a ranking part's k agents."""
    if task == "pairwise":
        return 1 / 3 if compares(study) else 0.5
    agents = next(len(part.agents) for part in study.parts if part.kind == "ranking")
    return 1 / math.factorial(agents)


def tasks(study: Study) -> list[str]:
    """The tasks the study's parts pose, pairwise first: the order in which every analysis shows them."""
    return [task for task in ("pairwise", "ranking") if any(part.kind == task for part in study.parts)]


def compares(study: Study) -> bool:
    """Whether a pairwise part asks a compare question (better, worse or no difference): then its task's answers
    are those, scored on the pairs whose ground truth decides which is better."""
    return any(
        study.questions[name].type == "compare"
        for part in study.parts
        if part.kind == "pairwise"
        for name in part.questions
    )
