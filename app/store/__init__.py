"""The survey's storage: the database (engine, sessions, migrations) and its tables."""
