"""The operator's web panel and its HTTP and WebSocket API: a process of its own that cncd
starts and stops with itself, a client of cncd's control socket like `cncctl`. It imports the
base layer, `geometry` and `interpreter` (the program preview), and `operator` (the control
socket's protocol limits); aiohttp is the `web` extra."""
