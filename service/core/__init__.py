"""The appliance's contracts that no one surface owns: what the live status holds and which commands exist.

The daemon, the publisher port and every publisher read these; nothing here imports a publisher, a device,
the store or the command line.
"""
