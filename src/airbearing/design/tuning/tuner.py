"""The public tuner: :func:`tune`, the fastest design of the family that meets a
specification, judged in the end by :func:`~airbearing.design.tuning.verdict.evaluate`."""

from __future__ import annotations

import copy
import math
import threading
from collections import OrderedDict
from dataclasses import replace

from airbearing.design.balancing import default_split
from airbearing.design.loops import make_loop
from airbearing.design.tuning.box import _corner_grid
from airbearing.design.tuning.family import _family, _stiffness
from airbearing.design.tuning.result import TuningResult, _verdict
from airbearing.design.tuning.screening import _Fast
from airbearing.design.tuning.search import _search
from airbearing.design.tuning.spec import Spec, _as_spec
from airbearing.design.tuning.verdict import evaluate
from airbearing.errors import InputError
from airbearing.progress import call

__all__ = ["tune"]

#: Results of this process's recent tunings, keyed by what decides them (testbed, loop,
#: split, spec): a notebook cell run again, or ``report`` after ``gains``, does not search
#: again. Every input is a frozen value, so an equal key is the same computation.
_DONE: OrderedDict = OrderedDict()
_DONE_SIZE = 16
_DONE_LOCK = threading.Lock()


def tune(
    testbed,
    loop: str,
    spec: Spec | None = None,
    *,
    split: str | None = None,
    progress=None,
) -> TuningResult:
    """Gains of the ``loop`` (``"balancing"`` or ``"attitude"``) of ``testbed`` for ``spec``.

    The fastest design of the family (the package docstring: the shortest worst-case
    settling time of the linear step and, attitude loop, of the rate-limited 180 deg slew)
    whose worst case over the uncertainty box meets every check of ``spec``; with
    ``spec.bandwidth_hz``, the design at that bandwidth.

    Parameters
    ----------
    testbed : Testbed
    loop : {"balancing", "attitude"}
    spec : Spec or dict, optional
        Default :class:`Spec` (45 deg, 6 dB, |S| <= 2, overshoot <= 5 %, fastest); a dict
        gives some of its fields (``{"phase_margin_deg": 50}``), the others at their
        defaults.
    split : {"mixed", "mechanical"}, optional
        Balancing PID split; default the split the testbed can run
        (:func:`~airbearing.design.balancing.default_split`).
    progress : callable, optional
        ``progress(what, done, total)`` (:mod:`airbearing.progress`).

    Returns
    -------
    TuningResult
        The gains (SI) and every requirement checked at the worst corner of the inertia
        (+-``spec.inertia_uncertainty``) and offset range; ``met`` is False, with the reason
        in ``message``, when the specification cannot be met.

    Notes
    -----
    The last 16 results of a process are kept: the same testbed, loop, split (balancing)
    and spec give a copy of the earlier answer at once.

    Raises
    ------
    InputError
        An unknown loop, a loop the testbed does not have, a bandwidth at or above Nyquist,
        a ``spec`` that is neither a Spec nor a dict of its fields.

    Examples
    --------
    The search checks a few hundred designs at every corner (several seconds, not run
    in the docstring test):

    >>> import airbearing as ab
    >>> tb = ab.load_testbed("cmg-yaw")
    >>> ab.tune(tb, "attitude").gains  # doctest: +SKIP
    {'K_p': 9.09..., 'K_i': 0.0239..., 'K_w': 6.59...}

    Options are checked before any work:

    >>> ab.tune(tb, "steering")
    Traceback (most recent call last):
    ...
    airbearing.errors.InputError: ...
    """
    progress = call(progress)
    spec = _as_spec(spec)
    opts = {"split": split} if loop == "balancing" else {}
    base = make_loop(testbed, loop, **opts)
    testbed = base.model.testbed  # a name or a file: the testbed it named
    if loop == "balancing" and split is None:
        split = default_split(testbed)
    key = (testbed, loop, split if loop == "balancing" else None, spec)
    with _DONE_LOCK:
        done = _DONE.get(key)
    if done is not None:
        progress("tuned before in this session: the same answer", 1, 1)
        return copy.deepcopy(done)  # a caller may change its dicts and lists
    nyq = math.pi / base.dt
    target = None
    if spec.bandwidth_hz is not None:
        target = 2 * math.pi * spec.bandwidth_hz
        if target >= nyq:
            raise InputError(
                f"bandwidth_hz={spec.bandwidth_hz}: at or above the Nyquist frequency "
                f"{nyq / (2 * math.pi):g} Hz of the {1 / base.dt:g} Hz sensor rate"
            )
    # a trim the sliders cannot reach fails the travel check whatever the gains: report it,
    # but do not let it drive the search
    fixed = {"slider travel (m)"} if base.trim.limit_violations else set()
    grid = _corner_grid(base, spec)
    corner_set = [(label, p) for label, p, _ in grid]
    fast = _Fast(base, spec, grid, fixed)
    # the balancing design model at the softest corner of the box (family.py)
    soft = None
    if loop == "balancing":
        soft = min(_stiffness(base.with_params(p))[1] for _, p, _ in grid)
    family = _family(base, soft)
    w_hi = 0.5 * nyq
    best, shapes = _search(fast, family, w_hi, target, progress)
    relaxed = best is None and (target is not None or spec.max_settling_time is not None)
    if relaxed:
        # nothing admissible at the requested bandwidth or settling time: the fastest
        # design that meets the rest, whose verdict says how far it falls short
        fast.spec = replace(spec, bandwidth_hz=None, max_settling_time=None)
        best, more = _search(fast, family, w_hi, None, progress)
        fast.spec, shapes = spec, shapes + more
    progress("the verdict at every corner")
    if best is not None:
        design = {"speed_rad_s": best.w, "damping": best.zeta, "integral_ratio": best.ratio}
        gains = best.gains
    else:  # nothing admissible anywhere: the candidate that misses least
        design = {"speed_rad_s": None, "damping": None, "integral_ratio": None}
        gains = fast.least[1]
    lp = base.with_gains(gains)
    checks, worst, per = evaluate(lp, spec, actuators=True, corner_set=corner_set)
    if best is not None and not relaxed and not _met(checks, fixed):
        # the search's frequency grid and python-control's disagree at the very edge of
        # a limit: step inside it along the same shape
        factor = 1.01 if _only_bandwidth_fails(checks, fixed) else 0.98
        w = design["speed_rad_s"]
        for _ in range(4):
            w *= factor
            trial = base.with_gains(family(w, best.zeta, best.ratio))
            res = evaluate(trial, spec, actuators=True, corner_set=corner_set)
            if _met(res[0], fixed):
                lp, (checks, worst, per), design["speed_rad_s"] = trial, res, w
                break
    design.update(
        objective=(
            "shortest worst-case settling (linear step into 2 %, rate-limited 180 deg slew "
            "into 1.5 deg; within 10 %: least overshoot)"
            + ("" if target is None else ", at the requested bandwidth")
        ),
        candidates=fast.count,
        shapes=shapes,
    )
    met = all(c.met for c in checks)
    result = TuningResult(
        loop=loop,
        split=split if loop == "balancing" else None,
        testbed=testbed.name,
        gains=lp.gains,
        spec=spec,
        checks=checks,
        met=met,
        worst_case=worst,
        message=_verdict(checks),
        corners=[(label, w) for label, w in per],
        design=design,
    )
    with _DONE_LOCK:
        _DONE[key] = copy.deepcopy(result)
        while len(_DONE) > _DONE_SIZE:
            _DONE.popitem(last=False)
    return result


def _met(checks, fixed) -> bool:
    return all(c.met for c in checks if c.name not in fixed)


def _only_bandwidth_fails(checks, fixed) -> bool:
    failed = [c.name for c in checks if not c.met and c.name not in fixed]
    return failed == ["bandwidth (Hz)"]
