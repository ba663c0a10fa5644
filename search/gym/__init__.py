"""Comparing agents in any Gymnasium environment that can be snapshotted: the coupled problem and its summaries."""
