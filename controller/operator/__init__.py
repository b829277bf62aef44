"""The operator's surfaces: the `cncctl` command and its sub-commands (check, inspect,
simulate, run), what they print and plot, and the daemon. May import anything below: runtime,
processes, generator modules, drivers, servo, geometry, base layer. Nothing imports this package.
"""
