"""Persistence: the result store (SQLite) and the MQTT outbox that delivers from it."""
