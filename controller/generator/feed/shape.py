"""The shape of a feed transition, for the planner: controller/transition_shape.py (the motion
loop's hold and override ramps share it, so it lives in the base layer)."""

from controller.transition_shape import PLATEAU_MARGIN, QUINTIC, TransitionShape

__all__ = ["PLATEAU_MARGIN", "QUINTIC", "TransitionShape"]
