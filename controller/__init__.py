"""phcnc controller: the three processes of the paper's section 4.1 and what they share.

Imports point one way (tests/test_layers.py keeps it so):

    operator -> runtime -> interpreter | generator | motion -> drivers
             -> generator modules (corners, ph, feed, dynamics) -> servo -> geometry
             -> base layer (errors, config, numeric, blocks, refpoints)

servo (the servo model of eq. 27, its prediction and the tool's true distance from the path)
is below the processes: the generator plans with it, motion and the simulated drives run it.

The base layer is the files in this folder: errors, the machine config, numpy helpers, and the
two things that flow between the processes (NC blocks, reference-point chunks).
"""

import ctypes
import os

# One BLAS thread in every process of the controller (set before numpy is first imported, and
# inherited by the processes it starts). OpenBLAS runs a matrix product above a small size on
# all cores, and its threads then spin waiting for more work: on 2 cores that doubled the CPU
# of planning a G1 program (a window's joints at once), and under `cncctl run` the spinning
# would take the core the motion process needs. The arrays here are far too small to gain
# from threads. A value set by the user is kept.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters
KEEP_FREED_BYTES = 64 << 20
MMAP_ABOVE_BYTES = 32 << 20


def _keep_freed_memory() -> None:
    """glibc returns a freed block of a few MB to the kernel at once (above its mmap threshold,
    or trimmed off the heap's top) and faults it back in page by page on the next allocation:
    planning allocates numpy arrays of that size all the time, and on a 100k-line program
    that was 3 s of kernel time in 16 s (0.04 s with these). Freed memory up to
    KEEP_FREED_BYTES stays with the process (peak RSS unchanged); fewer page faults also
    suit the motion process. Not on other C libraries, or where the user set MALLOC_*_."""
    if any(k in os.environ for k in ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_")):
        return
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return
    mallopt(M_MMAP_THRESHOLD, MMAP_ABOVE_BYTES)
    mallopt(M_TRIM_THRESHOLD, KEEP_FREED_BYTES)


_keep_freed_memory()

__version__ = "0.1.0"
