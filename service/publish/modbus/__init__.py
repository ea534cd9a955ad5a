"""The Modbus server and its register map."""
