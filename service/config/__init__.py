"""Configuration: the appliance file, the camera file, and the checks made before the daemon starts."""
