"""What a study's design means for every analysis of it: the tasks its parts pose and what guessing scores in each.
The report, the preregistration and the power simulation all read these, so they live below all three."""

from __future__ import annotations

import math

from app.survey.study import Study


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
