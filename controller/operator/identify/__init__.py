"""`cncctl identify`: the command, its drive loop (loop), and its report and config output
(report). Part of the operator layer: may import everything below it (runtime, motion,
drivers, servo, the base layer), as the other commands do."""
