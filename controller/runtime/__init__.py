"""The runtime that wires the three processes: interpreter and generator processes filling the
NC FIFO and the reference ring, the motion controller in this process (processes, stages), and
the headless run of a program through the servo model (simulation, streamed by
simulate_stream and summed up by simulate_figures). May import the processes
(controller.interpreter, controller.generator, controller.motion), drivers, controller.servo
and below.
"""
