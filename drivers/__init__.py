"""Drive backends (simulated card, CANopen CiA 402, serial pulse card) behind one interface."""
