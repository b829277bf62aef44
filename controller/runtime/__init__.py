"""The runtime that wires the three processes: interpreter and generator processes filling the
NC FIFO and the reference ring, the motion controller in this process (processes, stages), and
the headless run of a program through the servo model (simulation, streamed by sim_stream
and summed up by sim_figures). May import the processes
(controller.interpreter, controller.generator, controller.motion), drivers and below.
"""
