"""Response adapters over devices: the session window's keyboard (keyboard), a serial response box (serial_box).
The response type, the simulated observers and ``none`` stay in psyop.session.responses."""
