"""Every axis's discrete servo filter run together: one set of batched matrix products per block.

The streaming users (the sim card's plant, the model watch, the pre-compensation) ran one
filter_block per axis per call; at two frames a motion cycle the per-axis Python calls were
most of their cost. Here the axes' block matrices (controller.servo.model._block_matrices) are
stacked, zero-padded to the largest order (a padded state stays zero, so a 4th-order axis next
to a 5th-order one is exact), and one call filters all axes over any number of rows.
"""

from __future__ import annotations

import numpy as np

from controller.servo.model import BLOCK, DiscreteServo


def _pad(m: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    out = np.zeros(shape)
    out[tuple(slice(0, s) for s in m.shape)] = m
    return out


class StackedFilter:
    """Filters b/a of several axes over rows (m, n_axes) of inputs, keeping their states."""

    def __init__(self, servos: list[DiscreteServo]) -> None:
        order = max(s.order for s in servos)
        blocks = [s._blocks for s in servos]
        # obs (A, L, n), toeplitz (A, L, L), reach (A, n, L), powers (A, L + 1, n, n)
        self.obs = np.stack([_pad(b[0], (BLOCK, order)) for b in blocks])
        self.toeplitz = np.stack([b[1] for b in blocks])
        self.reach = np.stack([_pad(b[2], (order, BLOCK)) for b in blocks])
        self.powers = np.stack([_pad(b[3], (BLOCK + 1, order, order)) for b in blocks])
        self.orders = [s.order for s in servos]
        self.state = np.zeros((len(servos), order))
        self._cut: dict[int, tuple[np.ndarray, ...]] = {}  # chunk length -> _matrices

    def step(self, u: np.ndarray) -> np.ndarray:
        """Outputs (m, n_axes) for the next input rows (m, n_axes); the states go on."""
        out = np.empty(u.shape)
        x = self.state[:, :, None]
        for k0 in range(0, len(u), BLOCK):
            chunk = u[k0 : k0 + BLOCK].T[:, :, None]  # (A, m, 1)
            m = chunk.shape[1]
            obs, toeplitz, powers, reach = self._matrices(m)
            out[k0 : k0 + m] = (obs @ x + toeplitz @ chunk)[:, :, 0].T
            x = powers @ x + reach @ chunk
        self.state = x[:, :, 0]
        return out

    def _matrices(self, m: int) -> tuple[np.ndarray, ...]:
        """The block matrices cut to a chunk of m rows, contiguous (kept per m: a stream's
        chunks have a few lengths), which the products take a sixth faster than the views
        of the whole blocks (the same numbers)."""
        cut = self._cut.get(m)
        if cut is None:
            views = (
                self.obs[:, :m],
                self.toeplitz[:, :m, :m],
                self.powers[:, m],
                self.reach[:, :, BLOCK - m :],
            )
            cut = self._cut[m] = tuple(np.ascontiguousarray(v) for v in views)
        return cut

    def axis_state(self, axis: int) -> np.ndarray:
        """One axis's state, as filter_block keeps it (its own order)."""
        return self.state[axis, : self.orders[axis]].copy()
