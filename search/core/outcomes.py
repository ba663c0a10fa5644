"""How an agent's episode stands after a step: the codes every world reports and every shared layer reads,
kept here so that reading them needs no world's simulator."""

RUNNING, SUCCESS, COLLISION, TIMEOUT = 0, 1, 2, 3
OUTCOME_NAMES = ("running", "success", "collision", "timeout")
