"""The window-weighted joint least-squares fit of lines at known frequencies, for rig and model records alike.

:class:`LineFit` is built once per pinion speed and fits any number of
records of that speed (:mod:`uqgear.rig.features` reads its line amplitudes
and phasors). This module does no file I/O and no plotting.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

# From this many records on, the window-weighted basis is read once for all of them and the projection is
# one matrix product; below it the blocked projection is faster (docs/validation/diagnosis.md, Cost).
_BASIS_ROWS = 24
# Samples per block of the blocked projection: its phase table (block x 2 lines doubles) stays in cache.
_PROJECTION_BLOCK = 128


class _BlockedProjection:
    """The window-weighted projections of records on the cosines and sines of lines, block by block.

    Sample n = q B + r of a record: exp(-i w n) = exp(-i w q B) exp(-i w r), so
    the projection on line w is sum_q exp(-i w q B) sum_r y[q B + r] exp(-i w r)
    with y the windowed record: one matrix product of the record's blocks with a
    (B, 2 lines) table, then a weighted sum over the blocks. Its arithmetic is
    the full basis's, but it reads a table of kilobytes instead of the basis;
    the numbers agree with it to rounding (1e-13 relative, measured).
    """

    def __init__(self, angular: np.ndarray, taper: np.ndarray) -> None:
        self.size = taper.size
        self.blocks = -(-self.size // _PROJECTION_BLOCK)
        padded = np.zeros(self.blocks * _PROJECTION_BLOCK)
        padded[: self.size] = taper
        self.taper = padded.reshape(self.blocks, _PROJECTION_BLOCK)
        within = np.outer(np.arange(_PROJECTION_BLOCK), angular)
        self.table = np.concatenate([np.cos(within), -np.sin(within)], axis=1)
        across = np.outer(np.arange(self.blocks) * _PROJECTION_BLOCK, angular)
        self.cos_blocks, self.sin_blocks = np.cos(across), -np.sin(across)
        self.n_lines = angular.size

    def basis(self) -> np.ndarray:
        """(N, 1 + 2 lines): a column of ones, then cos(w n) and sin(w n) of each line, by the same angle sums.

        cos(w (q B + r)) = cos(w q B) cos(w r) - sin(w q B) sin(w r), and alike
        for the sine: four products a sample and line instead of two
        transcendental functions of an argument up to w N (more accurate
        too: the arguments stay below w max(B, N - B)).
        """
        k = self.n_lines
        cos_within, sin_within = self.table[None, :, :k], -self.table[None, :, k:]
        cos_across, sin_across = self.cos_blocks[:, None, :], -self.sin_blocks[:, None, :]
        columns = np.empty((self.blocks, _PROJECTION_BLOCK, 1 + 2 * k))
        columns[..., 0] = 1.0
        columns[..., 1 : 1 + k] = cos_across * cos_within - sin_across * sin_within
        columns[..., 1 + k :] = sin_across * cos_within + cos_across * sin_within
        return columns.reshape(self.blocks * _PROJECTION_BLOCK, 1 + 2 * k)[: self.size]

    def project(self, records: np.ndarray) -> np.ndarray:
        """(1 + 2 lines, R): the windowed sum, then the windowed projections on each line's cosine and sine."""
        count = records.shape[0]
        padded = np.zeros((count, self.blocks * _PROJECTION_BLOCK))
        padded[:, : self.size] = records
        windowed = padded.reshape(count, self.blocks, _PROJECTION_BLOCK) * self.taper
        inner = (windowed.reshape(count * self.blocks, _PROJECTION_BLOCK) @ self.table).reshape(
            count, self.blocks, 2 * self.n_lines
        )
        # exp(-i w r) = cos - i sin: the table holds cos(w r) and -sin(w r), the blocks cos(w q B), -sin(w q B)
        real, imaginary = inner[..., : self.n_lines], inner[..., self.n_lines :]
        cosine = np.einsum("rqk,qk->rk", real, self.cos_blocks) - np.einsum("rqk,qk->rk", imaginary, self.sin_blocks)
        sine = np.einsum("rqk,qk->rk", real, self.sin_blocks) + np.einsum("rqk,qk->rk", imaginary, self.cos_blocks)
        # the projection on sin(w n) is minus the imaginary part of sum y exp(-i w n)
        return np.concatenate([windowed.sum(axis=(1, 2))[:, None], cosine, -sine], axis=1).T


class LineFit:
    """Window-weighted joint least-squares fit of lines at known frequencies.

    Built once per pinion speed and applied to any number of records of that
    speed. Lines outside the band (above ``limit`` or below one bin) read NaN;
    a line within one bin of an earlier one is not fitted but reads that one's
    amplitude.
    """

    def __init__(self, frequencies: np.ndarray, fs: float, size: int, limit: float, taper: np.ndarray) -> None:
        self.size_out = frequencies.size
        # Below one bin a line cannot be told from the record's mean.
        self.inside = np.flatnonzero((frequencies <= limit) & (frequencies >= fs / size))
        chosen = frequencies[self.inside]
        # Lines closer than one bin cannot be separated: in the given order
        # (mesh harmonics first), a line joins the first fitted line within a
        # bin of it or becomes a fitted line itself.
        groups = np.zeros(chosen.size, dtype=int)
        centres: list[float] = []
        for index, frequency in enumerate(chosen):
            near = [number for number, centre in enumerate(centres) if abs(frequency - centre) < fs / size]
            if near:
                groups[index] = near[0]
            else:
                groups[index] = len(centres)
                centres.append(float(frequency))
        self.groups = groups
        self.n_centres = len(centres)
        if not centres:
            return
        self._blocked = _BlockedProjection(np.asarray(centres) * (2.0 * np.pi / fs), taper)
        # Columns: constant (the weighted mean), then cos and sin of each line.
        basis = self._blocked.basis()
        self.weighted = basis * taper[:, None]
        # Normal equations: one small Gram matrix per speed, shared by all records.
        self.factor = scipy.linalg.cho_factor(self.weighted.T @ basis)

    def coefficients(self, records: np.ndarray) -> np.ndarray:
        """Least-squares coefficients (1 + 2 n_centres, R): the mean, then the cos and sin of each line."""
        if records.shape[0] < _BASIS_ROWS:
            # a few records: streaming the whole basis (N x (1 + 2 lines) doubles, tens of MB) for
            # them costs several times the arithmetic; the blocked projection reads a small table
            projection = self._blocked.project(records)
        else:
            projection = self.weighted.T @ records.T
        return scipy.linalg.cho_solve(self.factor, projection)

    def amplitudes(self, records: np.ndarray) -> np.ndarray:
        """Amplitudes (R, L) of the lines in float64 records (R, N) without NaN."""
        result = np.full((records.shape[0], self.size_out), np.nan)
        if self.n_centres:
            coefficients = self.coefficients(records)
            amplitude = np.hypot(coefficients[1 : 1 + self.n_centres], coefficients[1 + self.n_centres :]).T
            result[:, self.inside] = amplitude[:, self.groups]
        return result

    def phasors(self, records: np.ndarray) -> np.ndarray:
        """Complex amplitudes (R, L), cos - i sin coefficients, whose moduli are :meth:`amplitudes`."""
        result = np.full((records.shape[0], self.size_out), np.nan, dtype=complex)
        if self.n_centres:
            coefficients = self.coefficients(records)
            phasor = (coefficients[1 : 1 + self.n_centres] - 1j * coefficients[1 + self.n_centres :]).T
            result[:, self.inside] = phasor[:, self.groups]
        return result


__all__ = ["LineFit"]
