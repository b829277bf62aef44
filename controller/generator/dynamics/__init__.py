"""Module 4, dynamics (eqs. 27-28): the servo model of Table II discretised by zero-order hold,
and the prediction of tracking and contour error. May import the base layer and
controller.geometry.
"""
