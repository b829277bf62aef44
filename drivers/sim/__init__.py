"""The `sim` backend: a simulated bit-pattern pulse card (frame FIFO, servo axes of Table II).
"""
