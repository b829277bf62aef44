"""phcnc controller: the three processes of the paper's section 4.1 and what they share.

Imports point one way (tests/test_layers.py keeps it so):

    operator -> runtime -> interpreter | generator | motion -> drivers
             -> generator modules (corners, ph, feed, dynamics) -> geometry
             -> base layer (errors, config, numeric, blocks, refpoints)

The base layer is the files in this folder: errors, the machine config, numpy helpers, and the
two things that flow between the processes (NC blocks, reference-point chunks).
"""

import os

# One BLAS thread in every process of the controller (set before numpy is first imported, and
# inherited by the processes it starts). OpenBLAS runs a matrix product above a small size on
# all cores, and its threads then spin waiting for more work: on 2 cores that doubled the CPU
# of planning a G1 program (a window's joints at once), and under `cncctl run` the spinning
# would take the core the motion process needs. The arrays here are far too small to gain
# from threads. A value set by the user is kept.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

__version__ = "0.1.0"
