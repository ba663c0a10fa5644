"""The solvers: the problem a solver searches (the `Problem` protocol and its optional capabilities), the
registry of summary methods (MCTS, N-first, random, cross-entropy, the representative solver, Agent Disagreements,
HIGHLIGHTS), the divergence reward, the top-K queue, the runner that turns a search job into summaries, and the
interface through which they reach a world (`search.core.domain`). They build on `search.core` and name no
world."""
