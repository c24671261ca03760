"""Automatic balancing: runs, metrics, the seed-000 comparison and sweeps, the two-step."""
