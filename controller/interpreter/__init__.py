"""Process 1, the NC interpreter (paper section 4.1): RS274/NGC and LinuxCNC NURBS blocks read
line by line into typed NC blocks, and the bounded NC FIFO that feeds the generator.

lexer -> codes -> state (modal state, mixes in moves: lines, arcs, NURBS; and work_offsets: work
offsets G54-G59, G10, G92) -> program (read_program, run from line, position_at_line,
final_offsets) -> fifo; extent (lengths, boxes, travel limits). May import the base layer
(offsets included) and controller.geometry.
"""
