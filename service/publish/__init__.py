"""Publishers: what the appliance tells the plant, one subpackage each (listed in ``registry.py``), and what they share:
the publisher port, the result payload, replies, exports and reports."""
