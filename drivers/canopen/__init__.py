"""The `canopen` backend: CiA 402 servo drives in cyclic synchronous position mode over CANopen
(python-can + canopen), and a simulated drive set that speaks the same protocol."""
