"""The agents layer: the DS-RNN network, its PPO training, evaluation, the agent registry with the scripted
robots, and the release of trained snapshots as the shipped agents (the weights and model cards beside this file).
It builds on `search.crowd.sim` only."""
