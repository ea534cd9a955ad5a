"""Device assembly: the drivers the sequencer drives, real or simulated, and the demo rig."""
