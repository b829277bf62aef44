"""Module 4, dynamics (eqs. 27-28): Figure 4's checks of a plan on the servo model's prediction
(contour violations, each stop's overshoot) and the braking model of stops. May import the base
layer, controller.geometry and controller.servo (the model and its prediction).
"""
