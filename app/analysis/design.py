"""What a study's design means for every analysis of it: the tasks its parts pose and what guessing scores in each.
The report, the preregistration and the power simulation all read these, so they live below all three."""

from __future__ import annotations

import math

from app.survey.study import Study


def chance(study: Study, task: str) -> float:
    """The accuracy of guessing: one of two agents, or one of the k! orders of a ranking part's k agents."""
    if task == "pairwise":
        return 0.5
    agents = next(len(part.agents) for part in study.parts if part.kind == "ranking")
    return 1 / math.factorial(agents)


def tasks(study: Study) -> list[str]:
    """The tasks the study's parts pose, pairwise first: the order in which every analysis shows them."""
    return [task for task in ("pairwise", "ranking") if any(part.kind == task for part in study.parts)]
