"""Sparkplug B: the appliance as an edge node on a plant's SCADA broker (``[sparkplug]``, off by default)."""
