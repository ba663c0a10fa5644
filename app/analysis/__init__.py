"""Reading a study's answers back: the answer table, exclusions, statistics, export, report and the bots."""
