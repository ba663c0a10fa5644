"""The study as the server runs it: the study file, screens and plans, answers, assignment, participant kinds and
the bundle."""
