"""Sampled vehicle models and their compiled functions."""
