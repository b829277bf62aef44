"""Process 1, the NC interpreter (paper section 4.1): RS274/NGC and LinuxCNC NURBS blocks read
line by line into typed NC blocks, and the bounded NC FIFO that feeds the generator.

lexer -> codes -> state (modal state, mixes in moves: lines, arcs, NURBS) -> program
(read_program) -> fifo. May import the base layer and controller.geometry.
"""
