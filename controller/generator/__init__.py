"""Process 2, the reference-point generator (paper Figure 4): NC blocks in, one reference point
per sample period out.

Its four modules are sub-packages, each a set of pure functions on plain dataclasses:
corners (sharp corner detection), ph (PH construction), feed (feedrate planning), dynamics
(Figure 4's checks on the servo model's prediction; the model itself is controller.servo).
Around them: replan (Figure 4's re-planning loop), window (look-ahead windows), repeats (what a
long run's windows share), sampling (reference points), baselines, plan (the process's API).
Modules may import the base layer, controller.geometry and the modules before them (ph may
import corners); dynamics and the files around the modules also controller.servo. Nothing here
imports the interpreter, motion or anything above.
"""
