"""cncd, the controller as a service: main (process and signals), machine (states and the job),
server (the control socket), protocol (its wire format), journal, log, notify (systemd).
Part of the operator surfaces: may import the runtime, the processes and everything below."""
