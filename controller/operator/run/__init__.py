"""`cncctl run`: the command (command.py), embedded or through cncd (remote.py), its view,
keys, exit codes and run from line N. May import what the operator package may; the daemon
takes the approach move and the result summary from here."""
