"""The survey server: reads a study bundle and never imports `search` or `torch`."""
