"""Alembic migrations of the survey database (a package so that installed copies can find them)."""
