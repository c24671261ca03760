"""Identification: seed-004 regression, output-error refinement, CMG yaw inertia."""
