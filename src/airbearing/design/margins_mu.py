"""Upper bounds of the structured singular value ``mu`` of a matrix for a diagonal complex
perturbation (one per channel): the D-scaled largest singular value
``min_D sigma(D M D^-1)`` (:func:`mu_upper_bound`, exact for two channels) and, at every
frequency at once, the Perron-scaled one it starts from (:func:`perron_mu_bounds`)."""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

__all__ = ["mu_upper_bound", "perron_mu_bounds"]


def mu_upper_bound(M: np.ndarray) -> float:
    """Upper bound of mu for a diagonal complex perturbation: min_D sigma(D M D^-1)."""
    n = M.shape[0]
    if n == 1:
        return float(abs(M[0, 0]))

    def f(logd):
        d = np.exp(np.concatenate([[0.0], logd]))
        # the largest singular value (np.linalg.norm(., 2) without its axis handling)
        return float(np.linalg.svd((d[:, None] * M) / d[None, :], compute_uv=False)[0])

    # Perron scaling of |M| as the start (Safonov's bound)
    A = np.abs(M) + 1e-300
    vals, vecs = np.linalg.eig(A)
    v = np.abs(vecs[:, np.argmax(vals.real)]) + 1e-300
    vals_l, vecs_l = np.linalg.eig(A.T)
    vl = np.abs(vecs_l[:, np.argmax(vals_l.real)]) + 1e-300
    d0 = np.sqrt(vl / v)
    x0 = np.log(d0[1:] / d0[0])
    res = minimize(f, x0, method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-10})
    return float(min(res.fun, f(x0), np.linalg.svd(M, compute_uv=False)[0]))


def perron_mu_bounds(M: np.ndarray) -> np.ndarray:
    """Upper bounds of mu at every frequency at once: ``sigma(D M D^-1)`` with the
    Perron scaling of ``|M|`` that :func:`mu_upper_bound` starts from (``M``: ``(n, m, m)``)."""
    A = np.abs(M) + 1e-300

    def perron(X):
        vals, vecs = np.linalg.eig(X)
        k = np.argmax(vals.real, axis=1)
        return np.abs(np.take_along_axis(vecs, k[:, None, None], axis=2)[..., 0]) + 1e-300

    d = np.sqrt(perron(np.swapaxes(A, 1, 2)) / perron(A))
    scaled = (d[:, :, None] * M) / d[:, None, :]
    return np.linalg.svd(scaled, compute_uv=False)[:, 0]  # the largest singular values
