"""The `serial` backend: a bit-pattern pulse card on a serial (USB CDC) link, its documented
frame protocol, and a simulated card that speaks it."""
