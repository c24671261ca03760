"""Closed-loop simulation: the compiled rollout and the standard scenarios."""
