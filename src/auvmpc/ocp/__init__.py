"""The tracking optimal control problem, stated once."""
