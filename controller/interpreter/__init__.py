"""Process 1, the NC interpreter (paper section 4.1): RS274/NGC and LinuxCNC NURBS blocks read
line by line into typed NC blocks, and the bounded NC FIFO that feeds the generator.

lexer -> codes -> state (InterpState: one line, made of parts: modal, the shared modal state;
work_offsets, WorkOffsets: G54-G59, G10, G92; moves, Moves: lines, arcs, NURBS) -> program
(read_program, run from line, position_at_line, final_offsets) -> fifo; extent (lengths,
boxes, travel limits). May import the base layer (offsets included) and controller.geometry.
"""
