"""The OPC UA server beside cncd (the Machine Tools companion model, OPC 40501-1): a process of
its own that reads cncd's control socket as a client. Part of the operator surfaces: imports
the base layer and the control socket's client and protocol, never the machine itself."""
