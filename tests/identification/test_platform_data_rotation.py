"""Gravity and a vertical field in body axes without the (N, 3, 3) rotation matrices.

``prepare_platform_logs`` rotates the lab gravity (and the testbed's field, when it lies
along one lab axis) into body axes with one row of ``R(q)`` instead of the whole matrix
(0.1-0.3 s of a 10^6-row identify); the numbers must be those of the matrix, to the bit,
so that the identification's answer does not move.
"""

from __future__ import annotations

import numpy as np

from airbearing import quaternion as quat
from airbearing.analysis.identification.data import _lab_axis_to_body, _rotation_row


def _attitudes(n: int = 2000) -> np.ndarray:
    rng = np.random.default_rng(7)
    q = rng.normal(size=(n, 4))
    q[:5] = [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, -1], [0.5, 0.5, -0.5, 0.5], [0, 0, 1, 0]]
    return quat.normalize(q)


def test_a_row_of_the_rotation_matrix_is_the_matrix_row_bit_for_bit():
    q = _attitudes()
    R = quat.rotation_matrix(q)
    for j in range(3):
        assert np.array_equal(_rotation_row(q, j), R[:, j, :])


def test_a_lab_axis_vector_in_body_axes_is_the_matrix_product_bit_for_bit():
    q = _attitudes()
    R = quat.rotation_matrix(q)
    for v in ([0.0, 0.0, -9.81], [0.0, 6e-4, 0.0], [2.5e-5, 0.0, 0.0]):
        v = np.array(v)
        assert np.array_equal(_lab_axis_to_body(q, v), np.einsum("...ji,...j->...i", R, v))
    # no field: zeros (the matrix product's zeros may carry a sign; equal as numbers)
    assert np.array_equal(_lab_axis_to_body(q, np.zeros(3)), np.zeros((q.shape[0], 3)))
