"""Highway driving (highway-env) as a Foil domain: the environment, its environment action, agents and clips."""
