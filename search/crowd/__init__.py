"""The crowd world as a Foil domain: the coupled crowd problem, its summaries, its batched rollouts for the
representative solver, and the domain itself (domain.py), over the world in search/crowd/sim and the agents in
search/crowd/agents."""
