"""Drive backends behind one interface (python-can style): base (the Drive class and its
hooks), errors, registry (backends by name) and one module or package per backend (sim).

May import the controller's base layer and the servo model of
controller.generator.dynamics.servo (what the simulated card clocks each axis through)."""
