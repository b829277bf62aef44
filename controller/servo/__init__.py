"""The servo model shared by every process: the axis loop of eq. 27 (Table II) discretised by
zero-order hold (model), its prediction of tracking and contour error (eq. 28), pre-compensation
of the reference, and the tool's true distance from the path (true_distance, window_search,
path_distance). The generator plans with it, the motion process re-times and checks with it,
the simulated drives clock their axes through it.

May import the base layer (controller.errors, config, numeric, blocks, ...) and
controller.geometry (path_distance evaluates NURBS blocks); nothing above.
"""
