"""Polynomial emulators: total-degree Legendre least-squares fits, and all runs' fits evaluated together."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .errors import CalibrationError


def total_degree_indices(dimensions: int, degree: int) -> np.ndarray:
    """Multi-indices (T, dimensions) of total degree <= ``degree``, constant first."""
    indices = [np.zeros(dimensions, dtype=int)]
    for total in range(1, degree + 1):
        for combination in _compositions(total, dimensions):
            indices.append(np.array(combination))
    return np.array(indices)


def _compositions(total: int, parts: int) -> list[tuple[int, ...]]:
    if parts == 1:
        return [(total,)]
    result = []
    for first in range(total, -1, -1):
        for rest in _compositions(total - first, parts - 1):
            result.append((first, *rest))
    return result


def legendre_table(z: np.ndarray, width: int, degree: int) -> np.ndarray:
    """Legendre polynomials P_0 .. P_degree (M, width, degree + 1) of inputs ``z`` (M, width) in [-1, 1]."""
    legendre = np.empty((z.shape[0], width, degree + 1))
    legendre[:, :, 0] = 1.0
    if degree >= 1:
        legendre[:, :, 1] = z
    for n in range(1, degree):
        legendre[:, :, n + 1] = ((2 * n + 1) * z * legendre[:, :, n] - n * legendre[:, :, n - 1]) / (n + 1)
    return legendre


class PolynomialEmulator:
    """Least-squares polynomial (Legendre, total degree) in inputs scaled to [-1, 1].

    Parameters
    ----------
    dimensions : int
        Number of inputs.
    degree : int
        Total degree.
    """

    def __init__(self, dimensions: int, degree: int = 3) -> None:
        self.dimensions = int(dimensions)
        self.degree = int(degree)
        self.indices = total_degree_indices(self.dimensions, self.degree)

    @property
    def n_terms(self) -> int:
        """Number of basis polynomials."""
        return int(self.indices.shape[0])

    def basis(self, z: np.ndarray) -> np.ndarray:
        """Basis matrix (M, T) of inputs ``z`` (M, dimensions) in [-1, 1]."""
        z = np.atleast_2d(z)
        legendre = legendre_table(z, self.dimensions, self.degree)
        columns = legendre[:, np.arange(self.dimensions)[None, :], self.indices]
        return np.prod(columns, axis=2)

    def fit(self, z: np.ndarray, values: np.ndarray) -> PolynomialEmulator:
        """Fit outputs ``values`` (N, F) at inputs ``z`` (N, dimensions); sets ``coefficients_`` and
        the leave-one-out residuals ``loo_residuals_`` (N, F) and RMS ``loo_rms_`` (F)."""
        matrix = self.basis(z)
        if matrix.shape[0] <= matrix.shape[1]:
            raise CalibrationError(
                f"emulator: {matrix.shape[0]} training runs for {matrix.shape[1]} polynomial "
                f"terms; expected more runs than terms"
            )
        q, r = np.linalg.qr(matrix)
        self.coefficients_ = np.linalg.solve(r, q.T @ values)
        leverage = np.sum(q**2, axis=1)
        residuals = values - matrix @ self.coefficients_
        self.loo_residuals_ = residuals / np.maximum(1.0 - leverage, 1e-8)[:, None]
        self.loo_rms_ = np.sqrt(np.mean(self.loo_residuals_**2, axis=0))
        return self

    def predict(self, z: np.ndarray) -> np.ndarray:
        """Outputs (M, F) at inputs (M, dimensions)."""
        return self.basis(z) @ self.coefficients_


class JointEmulator:
    """The emulators of all runs of one stage, evaluated together.

    Each run's emulator has the global inputs and the run's own T2 as inputs,
    so a basis term is a product of a polynomial in the global inputs (shared
    by all runs) and a Legendre polynomial in the run's own T2 input.

    Parameters
    ----------
    emulators : sequence of PolynomialEmulator
        Fitted, one per run, all of the same degree on ``n_global + 1`` inputs.
    n_global : int
        Number of global inputs.
    """

    def __init__(self, emulators: Sequence[PolynomialEmulator], n_global: int) -> None:
        self.n_global = n_global
        indices = emulators[0].indices  # (T, n_global + 1)
        global_indices = np.unique(indices[:, :n_global], axis=0)
        lookup = {tuple(row): number for number, row in enumerate(global_indices)}
        self.global_indices = global_indices  # (T_g, n_global)
        self.term_global = np.array([lookup[tuple(row[:n_global])] for row in indices])
        self.term_t2 = indices[:, n_global].copy()
        self.coefficients = np.stack([emulator.coefficients_ for emulator in emulators])  # (op, T, F)
        self.degree = emulators[0].degree

    def predict(self, z: np.ndarray) -> np.ndarray:
        """Outputs (M, op, F) at inputs ``z`` (M, n_global + op) in [-1, 1]: the global ones, then each run's T2."""
        legendre = legendre_table(z, z.shape[1], self.degree)
        n_global = self.n_global
        shared = legendre[:, np.arange(n_global)[None, :], self.global_indices].prod(axis=2)  # (M, T_g)
        own = legendre[:, n_global:, :]  # (M, op, degree+1)
        basis = shared[:, None, self.term_global] * own[:, :, self.term_t2]  # (M, op, T)
        return np.matmul(basis.transpose(1, 0, 2), self.coefficients).transpose(1, 0, 2)
