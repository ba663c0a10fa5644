"""The robustness tests use the analysis tests' bundle: every clip its own file with a summary, as the bots need."""

from tests.analysis.conftest import bundle_dir  # noqa: F401  (fixture used by name)
