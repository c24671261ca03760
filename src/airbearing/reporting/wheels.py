"""The demo report's reaction-wheel section: a yaw rig from tuned gains to a named friction.

The lab's most common rig (one wheel on a yaw bearing, ``rw-yaw``): the wheel loop tuned
to the default specification, a 90 deg slew of a rig whose wheel bearing has a Coulomb
friction the testbed file does not know, the discrepancy search naming it, and the
table's inertia identified by momentum exchange with the wheel, each checked against the
truth the section simulated.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np

from airbearing.analysis.discrepancy.search import discrepancy
from airbearing.analysis.identify import identify
from airbearing.analysis.simulation.scenarios import slew
from airbearing.design.tuning import tune
from airbearing.io.testbed import load_testbed
from airbearing.reporting.style import plain

__all__ = ["demo_section"]

#: N m: the wheel bearing's Coulomb friction the section hides in its log (a twentieth of
#: the RW-0.01's largest torque).
HIDDEN_FRICTION = 5e-5


def demo_section(report, *, quick: bool = False) -> None:
    """Reaction-wheel section of the demo report (``rw-yaw``)."""
    tb = load_testbed("rw-yaw")
    report.heading("Reaction wheels: a yaw rig from tuned gains to a named friction")
    report.paragraph(
        "rw-yaw: a yaw table (J_zz = 0.02 kg m^2 with the wheel locked) turned by one "
        "torque-commanded wheel with a Rocket Lab RW-0.01's data (2.865e-5 kg m^2, 1 mN m, "
        "6000 rpm). The attitude loop is seed 001's quaternion PID on the wheel; its gains "
        "are tuned to the default specification with the wheel's torque limit in the loop."
    )
    tuned = tune(tb, "attitude")
    report.table(
        [{"check": c.name, "value": c.value, "required": f"{c.sense} {c.limit:g}", "met": c.met}
         for c in tuned.checks if c.limit is not None],
        ["check", "value", "required", "met"],
    )  # fmt: skip
    duration = 40.0 if quick else 60.0
    run = slew(tb, angle_deg=90.0, duration=duration, gains=tuned.gains,
               effects={"wheel_coulomb_friction": HIDDEN_FRICTION}, seed=1)  # fmt: skip
    log = run.log
    found = discrepancy(tb, [log])
    named = found.effects.get("wheel_coulomb_friction")
    std = found.effect_std.get("wheel_coulomb_friction")
    value = None if named is None else float(np.ravel(named)[0])
    sd = None if std is None else float(np.ravel(std)[0])
    ident = identify(tb, [log])
    J = tb.body.yaw_inertia
    report.paragraph(
        f"A {duration:g} s slew of 90 deg with the tuned gains, flown by a rig whose wheel "
        f"bearing has a Coulomb friction of {HIDDEN_FRICTION:g} N m that the testbed file "
        "does not know. The log has the yaw, the gyro's wz, the wheel's measured speed ws1 "
        "and the commanded torque wc1. The discrepancy search, given the log and the file, "
        "names the wheel's friction; the identification finds the table's inertia from the "
        "momentum the wheel exchanges with it (the wheel's data-sheet inertia fixes the "
        "scale)."
    )
    rows = [
        {
            "what": "wheel_coulomb_friction (N m)",
            "truth": HIDDEN_FRICTION,
            "found": value,
            "std": sd,
            "rule": "within 3 std",
            "met": value is not None and abs(value - HIDDEN_FRICTION) < 3 * sd,
        },
        {
            "what": "J_zz (kg m^2)",
            "truth": J,
            "found": ident.inertia,
            "std": ident.std_inertia,
            "rule": "within 3 std",
            "met": abs(ident.inertia - J) < 3 * ident.std_inertia,
        },
        {
            "what": "gap after the named effect, in noise floors",
            "truth": 1.0,
            "found": found.gap_after / found.noise_floor,
            "std": None,
            "rule": "<= 1.5",
            "met": found.gap_after < 1.5 * found.noise_floor,
        },
    ]
    report.table(rows, ["what", "truth", "found", "std", "rule", "met"],
                 legend="no standard error: a ratio")  # fmt: skip
    t = log.t
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.4))
    ax[0].plot(t, np.degrees(log.column("yaw")), lw=1.2)
    ax[0].set_xlabel("time (s)")
    ax[0].set_ylabel("yaw (deg)")
    ax[0].set_title("Slew of 90 deg")
    ax[1].plot(t, log.column("ws1") * 60 / (2 * np.pi), lw=1.2, label="wheel speed")
    ax[1].set_xlabel("time (s)")
    ax[1].set_ylabel("wheel speed (rpm)")
    ax[1].set_title("The wheel takes the momentum")
    for a in ax:
        plain(a)
    fig.tight_layout()
    report.figure(fig, "The slew of rw-yaw with the tuned gains: yaw and wheel speed.")
    plt.close(fig)
