"""MQTT telemetry and commands."""
