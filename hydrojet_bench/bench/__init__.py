"""Bench sessions: the asyncio quasistatic loop over the real drivers, on the physical rig
or on the simulated one (the digital twin behind the byte-level emulators)."""
