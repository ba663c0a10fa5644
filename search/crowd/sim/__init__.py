"""The simulation layer: the crowd world, its crowd models (ORCA, social force), scenarios, what a robot observes,
the coupled simulator that steps every compared agent in one crowd, and a Gymnasium wrapper. Nothing here knows
about agents' networks, searches or clips."""
