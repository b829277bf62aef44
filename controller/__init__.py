"""phcnc controller: the three processes of the paper's section 4.1 and what they share.

Imports point one way (tests/test_layers.py keeps it so):

    operator -> runtime -> interpreter | generator | motion -> drivers
             -> generator modules (corners, ph, feed, dynamics) -> geometry
             -> base layer (errors, config, numeric, blocks, refpoints)

The base layer is the files in this folder: errors, the machine config, numpy helpers, and the
two things that flow between the processes (NC blocks, reference-point chunks).
"""

__version__ = "0.1.0"
