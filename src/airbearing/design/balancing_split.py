"""Which actuator carries each term of the seed-000 PID: :class:`PIDSplit`,
:data:`MECHANICAL` (seed 000 eq. 8) and :data:`MIXED` (seed 000 eqs. 5 and 7)."""

from __future__ import annotations

from dataclasses import dataclass

from airbearing.design.balancing_torques import dipole_for_torque, torque_to_sliders
from airbearing.errors import InputError

__all__ = ["ACTUATORS", "MECHANICAL", "MIXED", "PIDSplit"]

#: Actuators a PID term can be assigned to.
ACTUATORS = ("sliders", "magnetorquers")


@dataclass(frozen=True)
class PIDSplit:
    """Which actuator carries each term of the seed-000 PID.

    Each of ``proportional``, ``integral``, ``derivative`` is ``"sliders"`` or
    ``"magnetorquers"``. :data:`MECHANICAL` is seed 000 eq. 8, :data:`MIXED` eqs. 5 and 7.
    """

    proportional: str = "sliders"
    integral: str = "sliders"
    derivative: str = "sliders"

    def __post_init__(self) -> None:
        for term in ("proportional", "integral", "derivative"):
            v = getattr(self, term)
            if v not in ACTUATORS:
                raise InputError(f"PIDSplit {term}={v!r}: expected one of {', '.join(ACTUATORS)}")

    def carried_by(self, actuator: str) -> tuple[str, ...]:
        """The terms (``"proportional"``, ...) that ``actuator`` carries."""
        if actuator not in ACTUATORS:
            raise InputError(f"actuator {actuator!r}: expected one of {', '.join(ACTUATORS)}")
        return tuple(
            t for t in ("proportional", "integral", "derivative") if getattr(self, t) == actuator
        )

    @property
    def uses_magnetorquers(self) -> bool:
        return bool(self.carried_by("magnetorquers"))

    def torques(self, tau_p, tau_i, tau_d):
        """``(tau_sliders, tau_magnetorquers)``, the PID torque shared as assigned."""
        terms = {"proportional": tau_p, "integral": tau_i, "derivative": tau_d}
        zero = 0 * tau_p
        sl, mg = zero, zero
        for name, value in terms.items():
            if getattr(self, name) == "sliders":
                sl = sl + value
            else:
                mg = mg + value
        return sl, mg

    def commands(self, tau_p, tau_i, tau_d, *, g_hat, gravity, b_body, axes, masses):
        """The two actuator commands for the PID terms.

        Returns
        -------
        ds : (3,) slider displacements, m (seed 000 eq. 5 or 8, :func:`torque_to_sliders`).
        d : (3,) dipole, A m^2 (seed 000 eq. 7, :func:`dipole_for_torque`); zero when the
            magnetorquers carry nothing.
        """
        sl, mg = self.torques(tau_p, tau_i, tau_d)
        ds = torque_to_sliders(sl, g_hat, gravity, axes, masses)
        d = dipole_for_torque(mg, b_body) if self.uses_magnetorquers else 0 * mg
        return ds, d


#: Seed 000 eq. 8: all of P, I and D through the sliders.
MECHANICAL = PIDSplit("sliders", "sliders", "sliders")
#: Seed 000 eqs. 5 and 7: P and I through the sliders, D through the magnetorquers.
MIXED = PIDSplit("sliders", "sliders", "magnetorquers")
