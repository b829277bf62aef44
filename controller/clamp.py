"""clamp: np.clip's result (minimum of maximum) without its dispatch cost on small arrays."""

from __future__ import annotations

import numpy as np


def clamp(x: np.ndarray | float, lo: np.ndarray | float, hi: np.ndarray | float) -> np.ndarray:
    """np.minimum(np.maximum(x, lo), hi), which is how np.clip is defined; numpy 2's np.clip
    goes through Python wrappers costing ~1 us a call, and the planner calls it thousands of
    times per program on arrays of a few dozen elements."""
    return np.minimum(np.maximum(x, lo), hi)
