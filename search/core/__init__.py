"""The world-free core every world builds on."""
