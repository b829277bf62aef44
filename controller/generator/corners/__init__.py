"""Module 1, sharp corner detection (eqs. 13-15): curvature peaks of a NURBS above the threshold
and the zones around them. May import the base layer and controller.geometry.
"""
