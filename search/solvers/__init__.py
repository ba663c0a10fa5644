"""The search layer: the problem a solver searches (the `Problem` protocol, and the coupled problem of agents in
one crowd scored by the divergence reward), the solvers (MCTS, N-first, random, cross-entropy), the top-K queue,
the runner that turns a search job into summaries, and the summaries' replay check. It builds on `search.sim` and
`search.agents`."""
