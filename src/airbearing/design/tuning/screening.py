"""Candidates judged on the fast NumPy copies of the loop at the corners of the box."""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from airbearing.design.linearise import prune_states
from airbearing.design.loops import Loop, without_momentum_poles
from airbearing.design.margins import (
    PEAK_FRACTION,
    disk_margin_of_peak,
    mu_upper_bound,
    perron_mu_bounds,
)
from airbearing.design.tuning.fast_loop import _assemble, _freq, _mats, _step_response
from airbearing.design.tuning.fast_margins import _SUBGRID, _siso_margins
from airbearing.design.tuning.responses import (
    _HORIZON_GROWTH,
    _HORIZON_MAX,
    _actuator_limits,
    _actuator_values,
    _final_values,
    _horizon,
    _scenario_inputs,
    _step_metrics,
)
from airbearing.design.tuning.slew import _slew_response, slew_limit
from airbearing.design.tuning.spec import Spec

__all__: list[str] = []

_N_FREQ = 500  # frequency points of the search (the verdict uses analyse_loop's grid)
_W_MIN = 1e-4  # rad/s, slowest speed tried
# the search's limits sit this far inside the specification's, so that the verdict
# (python-control, its own frequency grid) agrees on the design the search returns
_INSIDE = {"pm": 0.05, "gm": 0.02, "ms": 0.002, "overshoot": 0.02, "bandwidth": 0.003}
_UNSTABLE_MISS = 100.0  # how far an unstable corner misses (a relative shortfall)
_REFINED_KEPT = 256  # plant responses on refinement grids kept per corner (16-32 kB each)


@dataclass
class _Assessment:
    ok: bool
    miss: float  # how far from admissible (0: admissible), a sum of relative shortfalls
    worst: dict  # worst values over the corners evaluated


class _Fast:
    """Every corner of a loop as NumPy matrices: candidates judged in milliseconds.

    The plant (discrete, zero-order hold), the delay and the controller are the Loop's
    own python-control pieces (:meth:`Loop.plant`, :meth:`Loop.delay`,
    :meth:`Loop.controller_ss`); only their interconnection, frequency responses and step
    responses are computed here. Corners are judged in the order they last failed, and a
    candidate stops at its first failing corner.
    """

    def __init__(self, base: Loop, spec: Spec, corner_set, fixed: set):
        self.base, self.spec, self.fixed = base, spec, fixed
        self.dt = base.dt
        nyq = math.pi / self.dt
        self.omega = np.logspace(math.log10(_W_MIN / 10), math.log10(nyq * (1 - 1e-9)), _N_FREQ)
        self.z = np.exp(1j * self.omega * self.dt)
        self.meas = list(base.used_measurements())
        self.ch = list(base.channels)
        self.axis = base.kind == "attitude" and base.model.dof == 1
        self.limits = {k: v for k, v in _actuator_limits(base).items() if k not in fixed}
        # the margin with every channel perturbed at once (evaluate's SIMULTANEOUS_* checks)
        self.simultaneous = len(self.ch) > 1
        self.count = 0
        self._k_refined: tuple = (None, {})  # the controller's responses off the grid
        self.least = None  # (miss, gains) of the candidate that misses least
        outs = [o for o in base.default_outputs() if o not in self.meas]
        ins = self.ch + list(base.disturbances)
        self.corners = []
        for label, p, _ in corner_set:
            lc = base.with_params(p)
            po = lc.plant(discrete=True, outputs=outs)
            pm = prune_states(po, self.meas, ins)
            # the body's states (not a wheel speed W<i>): stored momentum leaves them at rest
            body = np.array([not (x.startswith("W") and x[1:].isdigit()) for x in pm.state_labels])
            pm = pm[list(range(len(self.meas))), :]
            A, B, C, D = _mats(pm)
            nch = len(self.ch)
            self.corners.append(
                {
                    "label": label,
                    "loop": lc,
                    "Po": _mats(po),
                    "po_out": list(po.output_labels) + self.ch,
                    "Pm": (A, B, C, D),
                    "body": body,
                    "P_fr": _freq(A, B[:, :nch], C, D[:, :nch], self.z),
                    "P_refined": OrderedDict(),  # _mimo's plant responses off the grid
                }
            )
        self.delay = _mats(base.delay())
        # the search judges the vertices of the box; a candidate that ends a shape's
        # search is judged at every corner, and a corner it fails joins the vertices
        self.order = [i for i, (_, _, vertex) in enumerate(corner_set) if vertex]
        self.rest = [i for i, (_, _, vertex) in enumerate(corner_set) if not vertex]
        names = list(base.disturbances) + list(base.references)
        self.u = _scenario_inputs(base, names)
        self.slew_limit = slew_limit(base)
        # speed-commanded wheels: the controller's last states are the speed targets
        wh = base.model.testbed.wheels if base.wheels else None
        self.n_targets = wh.n if wh is not None and wh.command == "speed" else 0

    # -------------------------------------------------------------- pieces

    def _controller(self, gains):
        K = self.base.with_gains(gains).controller_ss(discrete=True)
        A, B, C, D = _mats(K)
        nm = len(self.meas)
        return (A, B, C, D), _freq(A, B[:, :nm], C, D[:, :nm], self.z)

    def _loops(self, Lw, S=None) -> dict:
        """Loop-at-a-time transfers from the MIMO ``L`` (frequency first) by channel:
        ``1 / (1 + L_j) = [(I + L)^-1]_jj`` (the Schur complement of the other channels,
        closed); ``S``: ``(I + L)^-1`` when already computed."""
        n = Lw.shape[1]
        if n == 1:
            out = {self.ch[0]: Lw[:, 0, 0]}
        else:
            S = np.linalg.inv(np.eye(n)[None] + Lw) if S is None else S
            out = {self.ch[j]: 1 / S[:, j, j] - 1 for j in range(n)}
        if self.axis:
            out["yaw"] = np.trace(Lw, axis1=1, axis2=2)
        return out

    @property
    def mu_limit(self) -> float:
        """The largest peak of ``mu(S - I/2)`` the specification allows: the balanced disk
        margin ``alpha = 1 / peak`` whose gain and phase meet its gain and phase margins
        (with the search's tolerance)."""
        gm = 10 ** ((self.spec.gain_margin_db + _INSIDE["gm"]) / 20)
        pm = math.radians(self.spec.phase_margin_deg + _INSIDE["pm"])
        # gain (1 + a/2)/(1 - a/2) = gm and phase 2 atan(a / 2) = pm, solved for alpha
        alpha = max(2 * (gm - 1) / (gm + 1), 2 * math.tan(pm / 2))
        return 1 / alpha

    def _mu_bound(self, S, floor: float = math.inf) -> np.ndarray:
        """An upper bound of ``mu(S - I/2)`` at each frequency (``S`` frequency first): the
        largest singular value of ``D M D^-1`` with the Perron scaling of ``|M|``, where
        :func:`~airbearing.design.margins.multiloop_disk_margin` starts its D-scaling (on
        these loops it ends there to 1e-5 at the peak), or with the ``D`` that balances the
        row and column 2-norms of ``|M|`` once, or none, whichever is least. Where that
        cheap bound says the check fails, the D-scaling of the report
        (:func:`mu_upper_bound`) decides, frequency by frequency from the largest, so a
        loose bound rejects nothing: near the Nyquist frequency, where the sampled plant's
        zeros make ``|M|`` nearly reducible, the Perron scaling of seed000-tabletop's mixed
        loop reads 70 where ``mu`` is 0.5.

        The bound is computed only where it can matter (branch and bound), from cruder
        upper bounds of it: ``min(||M||_F, sqrt(||M||_1 ||M||_inf)) >= sigma_max(M)``
        (sums), then ``sigma_max`` (one SVD), then the balanced scaling (one SVD), then the
        Perron scaling (two eigenproblems), each only where the one before reaches
        ``floor`` or the largest bound found. Elsewhere a cruder bound is returned: it lies
        below both, so the largest value and its frequency, and every value from ``floor``
        up, are those of the bound computed at every frequency. (cmg-yaw's loop has one
        measurement: there ``sigma_max`` is the bound wherever it matters; on a platform's
        mixed loop, the balanced scaling leaves the Perron scaling a tenth of the
        frequencies, where it is tighter.)"""
        M = S - 0.5 * np.eye(S.shape[1])
        absM = np.abs(M)
        bound = (1 + 1e-12) * np.minimum(
            np.sqrt(np.einsum("wij,wij->w", absM, absM)),
            np.sqrt(absM.sum(axis=1).max(axis=1) * absM.sum(axis=2).max(axis=1)),
        )
        level = np.zeros(bound.size, dtype=int)
        final = 3  # 0: the sums, 1: sigma_max, 2: balanced, 3: Perron-scaled

        def balanced(Mi):
            """sigma_max(D M D^-1), D balancing the row and column 2-norms of |M| once."""
            A = np.abs(Mi)
            cols, rows = np.sqrt((A * A).sum(axis=1)), np.sqrt((A * A).sum(axis=2))
            d = np.clip(np.sqrt(cols / np.maximum(rows, 1e-300)), 1e-6, 1e6)  # any D > 0 holds
            return np.linalg.svd((d[:, :, None] * Mi) / d[:, None, :], compute_uv=False)[:, 0]

        def refine(idx):
            for lv, fn in ((0, None), (1, balanced), (2, perron_mu_bounds)):
                at = idx[level[idx] == lv]
                if not at.size:
                    continue
                if fn is None:
                    bound[at] = np.linalg.svd(M[at], compute_uv=False)[:, 0]
                else:
                    bound[at] = np.fmin(bound[at], fn(M[at]))
            level[idx] += 1

        def reaching(threshold):
            return np.nonzero((level < final) & (bound >= threshold))[0]

        def largest_exact():
            """Refine, the largest first, until no cruder bound reaches the largest bound."""
            chunk = 16
            while True:
                top = bound[level == final].max() if (level == final).any() else -math.inf
                todo = reaching(top)
                if not todo.size:
                    return
                refine(todo[np.argsort(-bound[todo], kind="stable")[:chunk]])
                chunk *= 2

        for _ in range(final):
            refine(reaching(floor))
        for _ in range(bound.size):
            largest_exact()
            k = int(np.argmax(bound))
            if bound[k] < self.mu_limit:
                break
            exact = mu_upper_bound(M[k])
            bound[k] = exact
            if exact >= self.mu_limit:
                break
        largest_exact()
        return bound

    def _simultaneous(self, c, K, S) -> float:
        """The peak over frequency of :meth:`_mu_bound` at corner ``c`` (``1 / alpha`` of the
        multi-loop disk margin) from ``S = (I + L)^-1`` on the grid, its peaks refined on
        finer exact grids between their neighbours (two levels, as the channels' |S|).

        Only a peak that can decide the check is refined: none when the grid's peak
        already fails it, and otherwise those that come within :data:`PEAK_FRACTION` of
        the largest peak the check allows (:attr:`mu_limit`); the others are reported as
        the grid reads them."""
        bound = self._mu_bound(S, PEAK_FRACTION * self.mu_limit)
        peak = float(bound.max())
        if peak >= self.mu_limit:
            return peak  # fails on the grid already: refining only makes it fail more
        lw = np.log(self.omega)
        inner = bound[1:-1]
        local = np.nonzero((inner >= bound[:-2]) & (inner >= bound[2:]))[0] + 1
        eye = np.eye(S.shape[1])
        for i in local[bound[local] >= PEAK_FRACTION * self.mu_limit]:
            x0, x1 = lw[i - 1], lw[i + 1]
            for _ in range(2):
                xs = np.linspace(x0, x1, _SUBGRID)
                Lx = self._mimo(c, K, np.exp(xs))
                sub = self._mu_bound(np.linalg.inv(eye[None] + Lx))
                k = int(np.argmax(sub))
                peak = max(peak, float(sub[k]))
                x0, x1 = xs[max(k - 1, 0)], xs[min(k + 1, _SUBGRID - 1)]
        return peak

    def _mimo(self, c, K, K_fr_or_x):
        """``L`` at the actuator input (negative feedback), frequency first."""
        if isinstance(K_fr_or_x, np.ndarray) and K_fr_or_x.ndim == 3:
            K_fr, P_fr, z = K_fr_or_x, c["P_fr"], self.z
        else:
            x = np.atleast_1d(K_fr_or_x)
            z = np.exp(1j * x * self.dt)
            nm, nch = len(self.meas), len(self.ch)
            if self._k_refined[0] is not K:  # a new candidate
                self._k_refined = (K, {})
            key = x.tobytes()
            K_fr = self._k_refined[1].get(key)
            if K_fr is None:  # the corners' refinement grids often coincide
                A, B, C, D = K
                K_fr = _freq(A, B[:, :nm], C, D[:, :nm], z)
                self._k_refined[1][key] = K_fr
            # the plant's response on a refinement grid: the grids come from the fixed
            # search grid, so other candidates ask for the same ones at this corner
            P_fr = c["P_refined"].get(key)
            if P_fr is None:
                A, B, C, D = c["Pm"]
                P_fr = _freq(A, B[:, :nch], C, D[:, :nch], z)
                c["P_refined"][key] = P_fr
                if len(c["P_refined"]) > _REFINED_KEPT:
                    c["P_refined"].popitem(last=False)
            else:
                c["P_refined"].move_to_end(key)
        G = np.einsum("ijw,jkw->wik", K_fr, P_fr) * (z ** (-self.base.delay_samples))[:, None, None]
        return -G

    def margins(self, c, K, K_fr, *, simultaneous: bool = True) -> dict:
        """Stability and the worst margins over the channels at corner ``c``; with
        ``simultaneous`` and several channels (a stable loop) also the multi-loop disk
        margin's gain (dB) and phase (deg), ``ml_gm`` and ``ml_pm`` (else they can be added
        later by :meth:`add_simultaneous`)."""
        A = _assemble(c["Pm"], K, self.delay, len(self.meas), len(self.ch))[0]
        if self.base.wheels:  # without the neutral poles of stored wheel momentum
            nk, nd = K[0].shape[0], self.delay[0].shape[0]
            ctrl = np.arange(nk) < nk - self.n_targets
            mask = np.concatenate([c["body"], ctrl, np.zeros(nd, bool)])
            stable = bool(np.all(np.abs(without_momentum_poles(A, mask)) < 1))
        else:
            stable = bool(np.all(np.abs(np.linalg.eigvals(A)) < 1))
        Lw = self._mimo(c, K, K_fr)
        n = Lw.shape[1]
        S = np.linalg.inv(np.eye(n)[None] + Lw) if n > 1 else None
        loops = self._loops(Lw, S)
        res = {}
        seen: dict = {}  # the channels' refinements often ask for the same frequencies

        for name, L in loops.items():

            def exact(x, name=name):
                key = x.tobytes()
                if key not in seen:
                    seen[key] = self._loops(self._mimo(c, K, x))
                return seen[key][name]

            res[name] = _siso_margins(self.omega, L, stable, exact)
        wbs = [m["wb"] for m in res.values() if m["wb"] is not None]
        out = {
            "stable": stable,
            "pm": min(m["pm"] for m in res.values()),
            "gm": min(m["gm"] for m in res.values()),
            "ms": max(m["ms"] for m in res.values()),
            "wb": min(wbs) if wbs else 0.0,
            "_S": S,
        }
        if simultaneous:
            self.add_simultaneous(c, K, out)
        return out

    def add_simultaneous(self, c, K, m: dict) -> None:
        """Add ``ml_gm`` (dB) and ``ml_pm`` (deg), the multi-loop disk margin's gain and
        phase, to the :meth:`margins` ``m`` of corner ``c`` (a stable loop with several
        channels; nothing otherwise)."""
        if m["stable"] and m["_S"] is not None and "ml_pm" not in m:
            _, m["ml_gm"], m["ml_pm"] = disk_margin_of_peak(self._simultaneous(c, K, m["_S"]))

    def step(self, c, K, wb, settle: bool) -> dict:
        """Overshoot, settling and actuator peaks of the scenario at corner ``c``.

        The overshoot and the peaks come on the first horizon (:func:`_horizon`, where the
        transient is); only with ``settle`` does an unsettled response run longer.
        """
        lc = c["loop"]
        A, B, C, D = _assemble(c["Po"], K, self.delay, len(self.meas), len(self.ch))
        names = c["po_out"]
        final = _final_values(lc, A, B, C, D, self.u, names)
        b, d = B @ self.u, D @ self.u
        # only the outputs judged: the tracked ones and the actuators (wheel speeds for
        # the torques of speed-commanded wheels)
        keep = [i for i, x in enumerate(names) if x in final or x in self.ch or x[:6] == "true_W"]
        names, C, d = [names[i] for i in keep], C[keep], d[keep]
        duration = _horizon(wb)
        while True:
            n = int(round(duration / self.dt))
            Y = _step_response(A, b, C, d, n)
            t = np.arange(n) * self.dt
            y = dict(zip(names, Y, strict=True))
            overshoot, settling = _step_metrics(t, y, final)
            if not settle or math.isfinite(settling) or duration >= _HORIZON_MAX:
                break
            duration = min(duration * _HORIZON_GROWTH, _HORIZON_MAX)
        return {"overshoot": overshoot, "settling": settling, **_actuator_values(lc, t, y)}

    def slew(self, c, K) -> tuple:
        """Overshoot (%) and settling (s) of the rate-limited 180 deg slew at corner ``c``."""
        iy = c["po_out"].index(self.base.default_outputs()[0])
        return _slew_response(
            c["Po"], K, self.delay, len(self.meas), len(self.ch), iy, self.slew_limit, self.dt
        )

    # -------------------------------------------------------------- judging

    def _shortfalls(self, m: dict, s: dict | None) -> list:
        """Relative shortfalls of one corner (0 where met), with the search's tolerance."""
        sp = self.spec
        out = [
            (sp.phase_margin_deg + _INSIDE["pm"] - m["pm"]) / sp.phase_margin_deg,
            (sp.gain_margin_db + _INSIDE["gm"] - m["gm"]) / sp.gain_margin_db,
            (m["ms"] - sp.max_sensitivity + _INSIDE["ms"]) / sp.max_sensitivity,
        ]
        if "ml_pm" in m:  # every channel at once (the verdict's SIMULTANEOUS_* checks)
            out += [
                (sp.phase_margin_deg + _INSIDE["pm"] - m["ml_pm"]) / sp.phase_margin_deg,
                (sp.gain_margin_db + _INSIDE["gm"] - m["ml_gm"]) / sp.gain_margin_db,
            ]
        if s is not None:
            out.append((s["overshoot"] - sp.max_overshoot + _INSIDE["overshoot"]) / 5.0)
            if sp.max_settling_time is not None:
                out.append((s["settling"] - sp.max_settling_time) / sp.max_settling_time)
            out += [(s[k] - lim) / lim for k, lim in self.limits.items() if k in s]
        # an unlimited margin (no crossing) is inside by an unlimited amount
        return [0.0 if v == -math.inf else _UNSTABLE_MISS if not v <= math.inf else max(v, 0.0)
                for v in out]  # fmt: skip

    def assess(self, gains, *, every: bool = False) -> _Assessment:
        """Judge ``gains`` at the vertices of the box, stopping at the first that fails;
        ``every``: at every corner, and run the step responses until they settle.
        ``worst`` holds the worst values over the corners judged (the settling time
        only with ``every`` or a settling limit in the specification)."""
        settle = every or self.spec.max_settling_time is not None
        self.count += 1
        K, K_fr = self._controller(gains)
        worst = {"pm": math.inf, "gm": math.inf, "ms": 0.0, "wb": math.inf}
        if self.simultaneous:
            worst.update(ml_pm=math.inf, ml_gm=math.inf)
        worst.update(overshoot=0.0, settling=0.0, stable=True, unsettled=0, settled=0.0)
        miss = 0.0
        todo = list(self.order) + (list(self.rest) if every else [])
        for i in todo:
            c = self.corners[i]
            m = self.margins(c, K, K_fr, simultaneous=False)
            short = sum(self._shortfalls(m, None)) if m["stable"] else _UNSTABLE_MISS
            s = None
            if m["stable"] and (short == 0 or every):  # the rest only where it can matter
                self.add_simultaneous(c, K, m)
                short = sum(self._shortfalls(m, None))
            if m["stable"] and (short == 0 or every):
                s = self.step(c, K, m["wb"], settle)
                if every and self.slew_limit is not None:
                    s["slew_overshoot"], s["slew_settling"] = self.slew(c, K)
                short = sum(self._shortfalls(m, s))
            worst["stable"] &= m["stable"]
            for k, fn in (("pm", min), ("gm", min), ("ms", max), ("wb", min)):
                worst[k] = fn(worst[k], m[k])
            for k in ("ml_pm", "ml_gm"):
                if k in m:
                    worst[k] = min(worst[k], m[k])
            if s is not None:
                for k, v in s.items():
                    worst[k] = max(worst.get(k, 0.0), v)
                # the objective: corners that never settle, and the longest settling of
                # the others (step or slew)
                settles = max(s["settling"], s.get("slew_settling", 0.0))
                if math.isinf(settles):
                    worst["unsettled"] += 1
                else:
                    worst["settled"] = max(worst["settled"], settles)
            miss += short
            if short > 0:
                if i in self.rest:
                    self.rest.remove(i)
                else:
                    self.order.remove(i)
                self.order.insert(0, i)  # judge it first next time
                if not every:
                    break
        if self.spec.bandwidth_hz is not None:
            want = 2 * math.pi * self.spec.bandwidth_hz * (1 + _INSIDE["bandwidth"])
            miss += max(want - worst["wb"], 0.0) / want
        if self.least is None or miss < self.least[0]:
            self.least = (miss, dict(gains))
        return _Assessment(miss == 0.0, miss, worst)

    def bandwidth(self, gains) -> float:
        """Worst-case sensitivity bandwidth w_B of ``gains`` over the corners, rad/s."""
        self.count += 1
        K, K_fr = self._controller(gains)
        return min(
            self.margins(self.corners[i], K, K_fr, simultaneous=False)["wb"] for i in self.order
        )
