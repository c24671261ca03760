"""The stability report's signals and actuator channels in words, with their units.

Shared by its plots (:mod:`.stability_plots`) and its responses
(:mod:`.stability_responses`): legends and axis labels say ``slider 1 (m)``, not ``s1``.
"""

from __future__ import annotations

#: Signals and actuator channels in words, with units (legends and axis labels).
_WORDS = {
    "true_yaw": "yaw (deg)",
    "true_wz": "yaw rate (deg/s)",
    "true_th_x": "tilt about x (deg)",
    "true_th_y": "tilt about y (deg)",
    "true_th_z": "rotation about z (deg)",
    "s1": "slider 1 (m)",
    "s2": "slider 2 (m)",
    "s3": "slider 3 (m)",
    "mx": "dipole x (A m^2)",
    "my": "dipole y (A m^2)",
    "mz": "dipole z (A m^2)",
    "dd1": "gimbal 1 rate (rad/s)",
    "dd2": "gimbal 2 rate (rad/s)",
    "dd3": "gimbal 3 rate (rad/s)",
    "dd4": "gimbal 4 rate (rad/s)",
    "yaw": "yaw axis",
    **{f"wc{i}": f"wheel {i} command" for i in range(1, 7)},
}


def words(name: str) -> str:
    """A signal or channel name as a reader says it, with its unit (``s1`` -> slider 1 (m))."""
    return _WORDS.get(name, name.replace("_", " "))
