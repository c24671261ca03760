"""Identification: seed-004 regression, output-error refinement, CMG yaw inertia.

``identify_platform`` (dof-3 platforms, with or without sliding masses, gyro or
attitude-only logs) and ``identify_cmg_inertia`` (dof-1 CMG testbeds) return frozen
result objects whose ``to_json()`` is the ``airbearing identify`` JSON contract.
"""
