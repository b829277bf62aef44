"""Module 2, PH construction (eqs. 16-21): PH quintic fits of the corner zones, subdivided until
within e of the NURBS, G1 corner blends, and the run's path of pieces. May import the base
layer, controller.geometry and controller.generator.corners.
"""
