"""Drive backends behind one interface (python-can style): base (the Drive class and its
hooks), errors, registry (backends by name), homing (the host's side of Drive.home()) and one
package per backend (sim, canopen, serial).

May import the controller's base layer and controller.servo (the servo model the simulated
card and the simulated CANopen drive clock each axis through)."""
