"""`cncctl identify`: the command, its plan (the windows), its drive loop (loop), the fit
(result), its report and config output (report), and the client of cncd's identify (remote).
Part of the operator layer: may import everything below it (runtime, motion, drivers, servo,
the base layer), as the other commands do."""
