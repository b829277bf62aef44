"""Process 3, the motion controller: reference points from the ring, pulse counts per sample to
the drive, feedback checked (following and contour error), every fault a controlled stop.

loop (MotionController) uses checks, pulses, pacing, stopping, source and the drive interface;
ring is the shared-memory FIFO from the generator; realtime is SCHED_FIFO. May import the base
layer, controller.servo (hold and override re-time and check with the servo model, the
pre-compensation filter) and drivers.
"""
