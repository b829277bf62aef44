"""Curve geometry shared by every process: NURBS, PH quintics, line and arc curves, arc length
and its inverse, and the path of pieces in arc length.

Pure functions and immutable curves on numpy arrays. May import: controller.errors,
controller.config, controller.numeric, controller.blocks (the base layer) and nothing above.
"""
