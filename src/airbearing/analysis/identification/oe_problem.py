"""The multiple-shooting least-squares problem of the output-error fit (CasADi, IPOPT).

Decision vector ``v = [theta_hat (nf), z_0 (6), z_1 (6), ...]``: the scaled change of
the free parameters and, per shooting piece, a small rotation of its reference
attitude (rad) and its start rate (rad/s). Shooting pieces are cut inside each
segment of a log (between gaps); continuity joins the pieces of one segment, and each
segment starts afresh (its own initial state). The Model is rolled over each piece
with the LOGGED sample intervals (``Model.step_dt``: the interval an input), and the
residual of an outlier row is multiplied by zero. Residuals per sample: the attitude
as a small rotation ``2 vec(conj(q_log) (x) q_model)`` / sigma_q (rad) and, with a
gyro, the rate ``(w_model - w_log) / sigma_w``; attitude-only logs have the first only.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from airbearing.analysis.identification.data import PlatformData
from airbearing.analysis.identification.regression import PARAM_NAMES, theta_to_body
from airbearing.errors import SolverError
from airbearing.io.testbed import Body
from airbearing.models import quaternion as quat
from airbearing.models.model import build_model

__all__ = ["Problem", "THREADS"]

#: Threads evaluating the pieces' rollouts (CasADi map).
THREADS = 2


def _minors(M):
    """The seven principal minors of a symmetric 3x3 (CasADi): all >= 0 <=> M is PSD."""
    return ca.vertcat(
        M[0, 0],
        M[1, 1],
        M[2, 2],
        M[0, 0] * M[1, 1] - M[0, 1] ** 2,
        M[0, 0] * M[2, 2] - M[0, 2] ** 2,
        M[1, 1] * M[2, 2] - M[1, 2] ** 2,
        ca.det(M),
    )


def _pieces(n: int, steps: int | None) -> list[tuple[int, int]]:
    """Split ``n`` samples into near-equal pieces of about ``steps`` samples: (start, count)."""
    k = 1 if not steps else max(1, int(round(n / steps)))
    k = min(k, max(1, n // 2))
    edges = np.linspace(0, n, k + 1).round().astype(int)
    return [(int(a), int(b - a)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def _nearest_usable(d: PlatformData, k: int, stop: int) -> int:
    """The first usable row with a finite rate at or after ``k`` (before ``stop``), else ``k``."""
    ok = d.usable if d.usable is not None else np.ones(d.n, bool)
    ok = ok & np.all(np.isfinite(d.w), axis=1)
    for j in range(k, stop):
        if ok[j]:
            return j
    return k


def _inputs(model, d: PlatformData) -> np.ndarray:
    """Model inputs per sample (nu, N): sliders, dipole, lab field; no disturbance."""
    U = np.zeros((model.nu, d.n))
    U[model.index(["s1", "s2", "s3"], "u")] = d.s.T
    U[model.index(["mx", "my", "mz"], "u")] = d.dipole.T
    U[model.index(["bx_lab", "by_lab", "bz_lab"], "u")] = d.b_lab.T
    return U


def _sparse(nrow, ncol, rows, cols):
    """A CasADi sparsity from unique triplets, and the nonzero slot of each triplet."""
    rows, cols = np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)
    sp = ca.Sparsity.triplet(nrow, ncol, rows.tolist(), cols.tolist())
    order = np.lexsort((rows, cols))  # column-major, as CasADi stores nonzeros
    slot = np.empty(len(rows), dtype=np.int64)
    slot[order] = np.arange(len(rows))
    return sp, slot


class _Callback(ca.Callback):
    """A CasADi Function evaluated in Python (the NLP oracle pieces)."""

    def __init__(self, name, sp_in, sp_out, fn, jacobian=None):
        ca.Callback.__init__(self)
        self._sp_in, self._sp_out, self._fn, self._jac = sp_in, sp_out, fn, jacobian
        self.construct(name, {})

    def has_jacobian(self):
        return self._jac is not None

    def get_jacobian(self, name, inames, onames, opts):
        return self._jac

    def get_n_in(self):
        return len(self._sp_in)

    def get_n_out(self):
        return len(self._sp_out)

    def get_sparsity_in(self, i):
        return self._sp_in[i]

    def get_sparsity_out(self, i):
        return self._sp_out[i]

    def eval(self, arg):
        return self._fn(*[np.asarray(a.full()) for a in arg])


class Problem:
    """Multiple-shooting least squares with forward sensitivities of the Model's rollout.

    Decision vector ``v = [theta_hat (nf), z_0 (6), z_1 (6), ...]``: the scaled change of
    the free parameters from ``theta0`` and, per segment, a small rotation of the logged
    start attitude (rad) and the start rate (rad/s). One evaluation of the augmented
    rollout (states and their sensitivities to ``z`` and ``theta``, propagated through
    the Jacobian of ``Model.step``) gives the residuals, their Jacobian, the continuity
    defects and their Jacobian; IPOPT gets the gradient, the constraint Jacobian and a
    Gauss-Newton Hessian from it (constrained Gauss-Newton, Bock's multiple shooting).
    """

    def __init__(self, testbed, data, theta0, free, mass, margin, segment, substeps):
        J0, r0 = theta_to_body(theta0)
        tb = testbed.replace(
            body=Body(
                dof=3,
                mass=mass,
                inertia=tuple(map(tuple, J0)),
                cm_offset=tuple(r0),
                torque_noise=testbed.body.torque_noise,
            )
        )
        self.model = model = build_model(tb)
        self.data = data
        self.free = np.asarray(free, dtype=bool)
        self.fidx = np.flatnonzero(self.free)
        self.nf = nf = len(self.fidx)
        self.theta0 = np.asarray(theta0, float)
        self.js = js = float(np.trace(J0) / 3)
        self.scale = np.where(np.arange(9) < 6, js, 1e-3)
        self.mass, self.margin = mass, margin
        self.p_idx = model.index(PARAM_NAMES, "p")
        nx, nu, n_p = model.nx, model.nu, model.n_p
        nt = 6 + 9  # sensitivity columns: z (6), theta_hat (9, all parameters)

        # ---- SX building blocks
        x, S = ca.SX.sym("x", nx), ca.SX.sym("S", nx, nt)
        u, p = ca.SX.sym("u", nu), ca.SX.sym("p", n_p)
        ql, wl, sig = ca.SX.sym("ql", 4), ca.SX.sym("wl", 3), ca.SX.sym("sig", 2)
        mk = ca.SX.sym("mk")  # 1 for a usable row, 0 for an outlier row
        self._x, self._S, self._u, self._psym = x, S, u, p
        self.gyro = gyro = all(d.gyro for d in data)
        self.nr = 6 if gyro else 3  # residuals per sample
        y = model.h(x, u, p)
        qe = quat.qmul(quat.qconj(ql), y[0:4])
        e = 2 * qe[0] * qe[1:4] / sig[0]  # the small rotation log -> model, whitened
        if gyro:
            e = ca.vertcat(e, (y[4:7] - wl) / sig[1])
        e = mk * e
        self.res = ca.Function("res", [x, u, p, ql, wl, sig, mk], [e])
        self.res_aug = ca.Function(
            "res_aug",
            [ca.vertcat(x, ca.vec(S)), u, p, ql, wl, sig, mk],
            [e, ca.mtimes(ca.jacobian(e, x), S)],
        )
        qs, z = ca.SX.sym("qs", 4), ca.SX.sym("z", 6)
        x0 = ca.SX.zeros(nx)
        # [1, dtheta/2] normalised: the small rotation dtheta, smooth to every order at 0
        x0[0:4] = quat.qmul(qs, quat.normalize(ca.vertcat(1, z[0:3] / 2)))
        x0[4:7] = z[3:6]
        for i in model.lag_index:  # lagged gyro states start at the rate
            x0[i] = z[3 + "xyz".index(model.x_names[i][-1])]
        S0 = ca.horzcat(ca.jacobian(x0, z), ca.SX.zeros(nx, 9))
        self.start = ca.Function("start", [qs, z], [x0])
        self.start_aug = ca.Function("start_aug", [qs, z], [ca.vertcat(x0, ca.vec(S0))])
        xe, Se = ca.SX.sym("xe", nx), ca.SX.sym("Se", nx, nt)
        xn = self.start(qs, z)
        qd = quat.qmul(quat.qconj(xe[0:4]), xn[0:4])
        c = ca.vertcat(qd[1:4], xe[4:7] - xn[4:7])  # continuity defect (attitude, rate)
        dc_e = ca.mtimes(ca.jacobian(c, xe), Se)
        self.cont = ca.Function("cont", [xe, qs, z], [c])
        self.cont_aug = ca.Function(
            "cont_aug",
            [ca.vertcat(xe, ca.vec(Se)), qs, z],
            [c, dc_e[:, 6:], dc_e[:, :6], ca.jacobian(c, z)],
        )
        # physical consistency: the 7 principal minors of (Sigma_CM - margin I) / js >= 0
        th = ca.SX.sym("th", nf)
        tf = ca.SX(ca.DM(self.theta0))
        for k, i in enumerate(self.fidx):
            tf[i] = tf[i] + self.scale[i] * th[k]
        Jm = ca.vertcat(
            ca.horzcat(tf[0], tf[3], tf[4]),
            ca.horzcat(tf[3], tf[1], tf[5]),
            ca.horzcat(tf[4], tf[5], tf[2]),
        )
        r = tf[6:9]
        sigma_cm = 0.5 * ca.trace(Jm) * ca.SX.eye(3) - Jm - mass * ca.mtimes(r, r.T)
        phys = _minors((sigma_cm - margin * ca.SX.eye(3)) / js)
        lam = ca.SX.sym("lam", 7)
        self.theta_full = ca.Function("theta_full", [th], [tf])
        self.phys = ca.Function(
            "phys",
            [th, lam],
            [phys, ca.jacobian(phys, th), ca.hessian(ca.dot(lam, phys), th)[0]],
        )

        # ---- shooting pieces inside each segment of every log, grouped by (samples, steps)
        # piece: (log, first row, samples, steps, last in its segment, reference row)
        segs = []
        self.U, self.DT, self.M = [], [], []
        for li, d in enumerate(data):
            self.U.append(_inputs(model, d))
            self.DT.append(np.r_[np.diff(d.t), 0.0])  # logged interval after each row
            usable = d.usable if d.usable is not None else np.ones(d.n, bool)
            self.M.append(usable.astype(float))
            period = float(np.median(np.diff(d.t)))
            steps = None if segment is None else max(2, int(round(segment / period)))
            for a, b in d.segments or ((0, d.n),):
                pieces = _pieces(b - a, steps)
                for j, (k0, n) in enumerate(pieces):
                    last = j == len(pieces) - 1
                    ref = _nearest_usable(d, a + k0, a + k0 + n)
                    segs.append((li, a + k0, n, n - 1 if last else n, last, ref))
        self.segs = segs
        self.nseg = nseg = len(segs)
        self.nv = nf + 6 * nseg
        groups: dict = {}
        for j, (_, _, n, steps, _, _) in enumerate(segs):
            groups.setdefault((n, steps), []).append(j)
        self.groups = []

        def cat(arrays, j, n):
            li, k0 = segs[j][0], segs[j][1]
            return arrays[li][..., k0 : k0 + n]

        for (n, steps), members in groups.items():
            qs_g = np.column_stack([data[segs[j][0]].q[segs[j][5]] for j in members])
            U_g = np.hstack([cat(self.U, j, n) for j in members])
            Q_g = np.hstack([data[segs[j][0]].q[segs[j][1] : segs[j][1] + n].T for j in members])
            W_g = np.hstack([data[segs[j][0]].w[segs[j][1] : segs[j][1] + n].T for j in members])
            W_g = np.nan_to_num(W_g)  # attitude-only: unused
            DT_g = np.hstack([cat(self.DT, j, n) for j in members])[None, :]
            M_g = np.hstack([cat(self.M, j, n) for j in members])[None, :]
            plain, aug = self._segment_functions(n, steps, substeps)
            self.groups.append(
                (
                    np.array(members),
                    n,
                    plain.map(len(members), "thread", THREADS),
                    aug.map(len(members), "thread", THREADS),
                    qs_g,
                    U_g,
                    Q_g,
                    W_g,
                    DT_g,
                    M_g,
                )
            )
        self.mask = np.concatenate([cat(self.M, j, segs[j][2]) for j in range(nseg)]) > 0
        # boundaries between consecutive pieces of one segment
        self.bounds = [j for j in range(nseg) if not segs[j][4]]
        self.ncont = 6 * len(self.bounds)
        self.ng = self.ncont + 7
        self._cache_key = None
        self._build_patterns()

    def _segment_functions(self, n, steps, substeps):
        """Rollout of one piece: plain (residuals, end state) and augmented (+ sensitivities)."""
        model = self.model
        nx = model.nx
        step = model.step_dt(substeps)  # the logged interval is an input (jitter)
        x, S, u, p = self._x, self._S, self._u, self._psym
        h = ca.SX.sym("h")
        xn = step(x, u, p, h)
        dp = np.zeros((model.n_p, 9))
        dp[self.p_idx, np.arange(9)] = self.scale
        A = ca.jacobian(xn, x)
        B = ca.mtimes(ca.jacobian(xn, p), ca.DM(dp))
        Sn = ca.mtimes(A, S) + ca.horzcat(ca.SX.zeros(nx, 6), B)
        step_aug = ca.Function(
            "step_aug", [ca.vertcat(x, ca.vec(S)), u, p, h], [ca.vertcat(xn, ca.vec(Sn))]
        )
        pm, z, qs = ca.MX.sym("p", model.n_p), ca.MX.sym("z", 6), ca.MX.sym("qs", 4)
        U, Q = ca.MX.sym("U", model.nu, n), ca.MX.sym("Q", 4, n)
        W, sig = ca.MX.sym("W", 3, n), ca.MX.sym("sig", 2)
        DT, M = ca.MX.sym("DT", 1, n), ca.MX.sym("M", 1, n)
        out = []
        for aug in (False, True):
            x0 = self.start_aug(qs, z) if aug else self.start(qs, z)
            fn = step_aug if aug else step
            if steps > 0:
                X = fn.mapaccum(steps)(x0, U[:, :steps], pm, DT[:, :steps])
                cols = ca.horzcat(x0, X[:, : n - 1]) if n > 1 else x0
                x_end = X[:, steps - 1]
            else:
                cols, x_end = x0, ca.MX.zeros(x0.shape[0])
            res = self.res_aug if aug else self.res
            r = res.map(n)(cols, U, ca.repmat(pm, 1, n), Q, W, ca.repmat(sig, 1, n), M)
            outs = [r[0], r[1], x_end] if aug else [r, x_end]
            name = "segment_aug" if aug else "segment"
            out.append(ca.Function(name, [pm, z, qs, U, Q, W, sig, DT, M], outs))
        return out

    def _build_patterns(self):
        nf, nv = self.nf, self.nv
        # constraint Jacobian: continuity rows (theta, z_j, z_j+1), physical rows (theta)
        rows, cols = [], []
        for b, j in enumerate(self.bounds):
            rr = 6 * b + np.arange(6)
            cc = np.r_[0:nf, nf + 6 * j : nf + 6 * j + 12]
            R, C = np.meshgrid(rr, cc, indexing="ij")
            rows.append(R.ravel())
            cols.append(C.ravel())
        R, C = np.meshgrid(self.ncont + np.arange(7), np.arange(nf), indexing="ij")
        rows.append(R.ravel())
        cols.append(C.ravel())
        self.jac_rows, self.jac_cols = np.concatenate(rows), np.concatenate(cols)
        self.jac_sp, self.jac_slot = _sparse(self.ng, nv, self.jac_rows, self.jac_cols)
        # upper triangle of the Hessian: theta-theta, theta-z_j, z_j-z_j
        rows, cols = [], []
        iu = np.triu_indices(nf)
        rows.append(iu[0])
        cols.append(iu[1])
        for j in range(self.nseg):
            zc = nf + 6 * j + np.arange(6)
            R, C = np.meshgrid(np.arange(nf), zc, indexing="ij")
            rows.append(R.ravel())
            cols.append(C.ravel())
            iz = np.triu_indices(6)
            rows.append(zc[iz[0]])
            cols.append(zc[iz[1]])
        self.hess_rows, self.hess_cols = np.concatenate(rows), np.concatenate(cols)
        self.hess_sp, self.hess_slot = _sparse(nv, nv, self.hess_rows, self.hess_cols)

    # ---- evaluation
    def _p(self, th):
        tf = np.asarray(self.theta_full(th)).ravel()
        p = self.model.p0.copy()
        p[self.p_idx] = tf
        return p

    def _split(self, v):
        return v[: self.nf], v[self.nf :].reshape(self.nseg, 6).T

    def evaluate(self, v, sig, derivatives):
        """Residuals per segment, end states and, optionally, their sensitivities."""
        th, Z = self._split(v)
        p = self._p(th)
        E = [None] * self.nseg
        JE = [None] * self.nseg
        XE = [None] * self.nseg
        nr = self.nr
        for members, n, plain, aug, qs_g, U_g, Q_g, W_g, DT_g, M_g in self.groups:
            fn = aug if derivatives else plain
            out = fn(p, Z[:, members], qs_g, U_g, Q_g, W_g, sig, DT_g, M_g)
            e = np.asarray(out[0]).reshape(nr, n, len(members), order="F")
            xe = np.asarray(out[-1])
            if derivatives:
                je = np.asarray(out[1]).reshape(nr, 15, n, len(members), order="F")
            for k, j in enumerate(members):
                E[j] = e[:, :, k].T.ravel()  # sample-major: [e_q, (e_w)] per sample
                XE[j] = xe[:, k]
                if derivatives:
                    JE[j] = je[:, :, :, k].transpose(2, 0, 1).reshape(nr * n, 15)
        return E, JE, XE, th, Z

    def constraints(self, v, XE, derivatives, lam_phys=None):
        th, Z = self._split(v)
        nx = self.model.nx
        c = np.zeros(self.ncont)
        blocks = []
        for b, j in enumerate(self.bounds):
            li, ref = self.segs[j + 1][0], self.segs[j + 1][5]
            qs = self.data[li].q[ref]
            if derivatives:
                cv, dth, dz0, dz1 = self.cont_aug(XE[j], qs, Z[:, j + 1])
                c[6 * b : 6 * b + 6] = np.asarray(cv).ravel()
                blocks.append(
                    np.hstack([np.asarray(dth)[:, self.fidx], np.asarray(dz0), np.asarray(dz1)])
                )
            else:
                c[6 * b : 6 * b + 6] = np.asarray(self.cont(XE[j][:nx], qs, Z[:, j + 1])).ravel()
        lam = np.zeros(7) if lam_phys is None else lam_phys
        g_phys, j_phys, h_phys = self.phys(th, lam)
        g = np.concatenate([c, np.asarray(g_phys).ravel()])
        return g, blocks, np.asarray(j_phys), np.asarray(h_phys)

    def _derivatives(self, v, sig):
        key = (v.tobytes(), sig.tobytes())
        if self._cache_key != key:
            E, JE, XE, th, Z = self.evaluate(v, sig, True)
            self._cache = (E, JE, XE)
            self._cache_key = key
        return self._cache

    def gram(self, JE, rows=slice(None)):
        """Gauss-Newton blocks ``J^T J`` (theta-theta, theta-z_j, z_j-z_j) for residual ``rows``."""
        fi = np.r_[6 + self.fidx]
        Htt = np.zeros((self.nf, self.nf))
        Htz, Hzz = [], []
        for Jj in JE:
            Jj = Jj.reshape(-1, self.nr, 15)[:, rows, :].reshape(-1, 15)
            Jt, Jz = Jj[:, fi], Jj[:, :6]
            Htt += Jt.T @ Jt
            Htz.append(Jt.T @ Jz)
            Hzz.append(Jz.T @ Jz)
        return Htt, Htz, Hzz

    # ---- the oracle functions IPOPT calls (noise levels fixed per solve in self.sig)
    def f_fn(self, v):
        E, _, _, _, _ = self.evaluate(v.ravel(), self.sig, False)
        return [ca.DM(0.5 * sum(float(e @ e) for e in E))]

    def g_fn(self, v):
        v = v.ravel()
        _, _, XE, _, _ = self.evaluate(v, self.sig, False)
        g, _, _, _ = self.constraints(v, XE, False)
        return [ca.DM(g)]

    def grad_fn(self, v, *_):
        v = v.ravel()
        E, JE, _ = self._derivatives(v, self.sig)
        grad = np.zeros(self.nv)
        fi = 6 + self.fidx
        for j, (e, Jj) in enumerate(zip(E, JE, strict=True)):
            grad[: self.nf] += Jj[:, fi].T @ e
            grad[self.nf + 6 * j : self.nf + 6 * j + 6] = Jj[:, :6].T @ e
        f = 0.5 * sum(float(e @ e) for e in E)
        return [ca.DM(f), ca.DM(grad).T]

    def jac_fn(self, v, *_):
        v = v.ravel()
        _, _, XE = self._derivatives(v, self.sig)
        g, blocks, j_phys, _ = self.constraints(v, XE, True)
        vals = np.concatenate([b.ravel() for b in blocks] + [j_phys.ravel()])
        nz = np.zeros(self.jac_sp.nnz())
        nz[self.jac_slot] = vals
        return [ca.DM(g), ca.DM(self.jac_sp, nz)]

    def hess_fn(self, v, _p, lam_f, lam_g):
        v = v.ravel()
        lam_f = float(np.asarray(lam_f).ravel()[0])
        _, JE, XE = self._derivatives(v, self.sig)
        _, _, _, h_phys = self.constraints(v, XE, False, np.asarray(lam_g).ravel()[self.ncont :])
        Htt, Htz, Hzz = self.gram(JE)
        Htt = lam_f * Htt + h_phys
        iu = np.triu_indices(self.nf)
        iz = np.triu_indices(6)
        vals = [Htt[iu]]
        for j in range(self.nseg):
            vals.append(lam_f * Htz[j].ravel())
            vals.append(lam_f * Hzz[j][iz])
        nz = np.zeros(self.hess_sp.nnz())
        nz[self.hess_slot] = np.concatenate(vals)
        return [ca.DM(self.hess_sp, nz)]

    def solver(self, max_iter):
        nv, ng = self.nv, self.ng
        dv, one, dg = ca.Sparsity.dense(nv, 1), ca.Sparsity.dense(1, 1), ca.Sparsity.dense(ng, 1)
        dp = ca.Sparsity.dense(0, 1)  # the NLP has no parameters
        grad_cb = _Callback("oe_grad_f", [dv, dp], [one, ca.Sparsity.dense(1, nv)], self.grad_fn)
        jac_cb = _Callback("oe_jac_g", [dv, dp], [dg, self.jac_sp], self.jac_fn)
        # f and g know their first derivatives (CasADi asks for them once, for the multipliers)
        f_jac = _Callback(
            "jac_oe_f", [dv, one], [ca.Sparsity.dense(1, nv)], lambda v, _f: self.grad_fn(v)[1:]
        )
        g_jac = _Callback("jac_oe_g", [dv, dg], [self.jac_sp], lambda v, _g: self.jac_fn(v)[1:])
        f_cb = _Callback("oe_f", [dv], [one], self.f_fn, f_jac)
        g_cb = _Callback("oe_g", [dv], [dg], self.g_fn, g_jac)
        hess_cb = _Callback("oe_hess_l", [dv, dp, one, dg], [self.hess_sp], self.hess_fn)
        self._cbs = [grad_cb, jac_cb, f_jac, g_jac, f_cb, g_cb, hess_cb]  # keep them alive
        v = ca.MX.sym("v", nv)
        nlp = {"x": v, "f": f_cb(v), "g": g_cb(v)}
        opts = {
            "ipopt.print_level": 0,
            "print_time": False,
            "ipopt.sb": "yes",
            "ipopt.tol": 1e-9,
            "ipopt.max_iter": max_iter,
            "grad_f": grad_cb,
            "jac_g": jac_cb,
            "hess_lag": hess_cb,
        }
        return ca.nlpsol("output_error", "ipopt", nlp, opts)

    def z_start(self) -> np.ndarray:
        """Start of each piece: no rotation from its reference attitude, the logged rate."""
        z = np.zeros((6, self.nseg))
        for j, seg in enumerate(self.segs):
            w = self.data[seg[0]].w[seg[5]]
            z[3:6, j] = np.where(np.isfinite(w), w, 0.0)
        return z

    def solve(self, v0, sig, max_iter):
        self.sig = np.asarray(sig, float)
        solver = self.solver(max_iter)
        lbg = np.zeros(self.ng)
        ubg = np.concatenate([np.zeros(self.ncont), np.full(7, np.inf)])
        sol = solver(x0=v0, lbg=lbg, ubg=ubg)
        return np.asarray(sol["x"]).ravel(), solver.stats()

    def raw_residuals(self, v, sig):
        """Unwhitened residuals of the usable rows (nr, samples): attitude (rad), rate (rad/s)."""
        E, _, _, _, _ = self.evaluate(v, sig, False)
        R = np.concatenate([e.reshape(-1, self.nr) for e in E]).T[:, self.mask]
        return R * np.r_[np.full(3, sig[0]), np.full(self.nr - 3, sig[1])][:, None]

    def covariance(self, v, sig, weights=((1.0, 1.0),)):
        """Covariance of the free parameters (scaled) from the equality-constrained Fisher matrix.

        The Gauss-Newton matrix of the multiple-shooting problem bordered by the continuity
        Jacobian (KKT matrix); its inverse's parameter block equals the inverse Fisher
        information of single shooting (parameters plus each log's initial state).
        Each ``(wq, ww)`` of ``weights`` rescales the attitude and rate residuals'
        information (other noise levels, e.g. the sensor specification's).
        """
        import scipy.sparse as sps
        import scipy.sparse.linalg as spla

        E, JE, XE, _, _ = self.evaluate(v, sig, True)
        Hq = self.gram(JE, slice(0, 3))
        Hw = self.gram(JE, slice(3, 6))
        nf, nv = self.nf, self.nv
        _, blocks, _, _ = self.constraints(v, XE, True)
        C = sps.lil_matrix((self.ncont, nv))
        for b, j in enumerate(self.bounds):
            C[6 * b : 6 * b + 6, :nf] = blocks[b][:, :nf]
            C[6 * b : 6 * b + 6, nf + 6 * j : nf + 6 * j + 12] = blocks[b][:, nf:]
        C = C.tocsc()
        out = []
        for wq, ww in weights:
            H = sps.lil_matrix((nv, nv))
            H[:nf, :nf] = wq * Hq[0] + ww * Hw[0]
            for j in range(self.nseg):
                zc = slice(nf + 6 * j, nf + 6 * j + 6)
                H[:nf, zc] = wq * Hq[1][j] + ww * Hw[1][j]
                H[zc, :nf] = (wq * Hq[1][j] + ww * Hw[1][j]).T
                H[zc, zc] = wq * Hq[2][j] + ww * Hw[2][j]
            K = sps.bmat([[H.tocsc(), C.T], [C, None]], format="csc")
            rhs = np.zeros((K.shape[0], nf))
            rhs[np.arange(nf), np.arange(nf)] = 1.0
            try:
                sol = spla.splu(K).solve(rhs)
            except RuntimeError as e:
                raise SolverError(
                    f"output-error fit: the Fisher information is singular ({e}); the logs "
                    "cannot separate the parameters"
                ) from e
            cov = sol[:nf, :nf]
            out.append(0.5 * (cov + cov.T))
        return out
