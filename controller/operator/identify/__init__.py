"""`cncctl identify`: the command, its drive loop, and its report and config output."""
