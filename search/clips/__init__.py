"""The clips layer: a summary read back as a scene (where every agent and person is at every step) and the
renderer that draws it as an H.264 clip with a poster and a contact sheet. It reads summaries; it never runs a
search."""
