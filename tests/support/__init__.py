"""What tests and benchmarks share: a live `foil serve` process, a throwaway PostgreSQL server, study files and
bundles for the survey, form reading, simulated crowds of participants, small networks. Plain modules, no
fixtures: the conftest files turn these into fixtures, and test modules never import each other."""
