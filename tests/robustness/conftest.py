"""The robustness tests use the survey tests' fixtures with the analysis tests' bundle: every clip its own file
with a summary, as the bots need."""

from tests.analysis.conftest import bundle_dir  # noqa: F401  (fixtures used by name)
from tests.app.conftest import database_url, make_client  # noqa: F401
