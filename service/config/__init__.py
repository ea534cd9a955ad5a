"""The configuration's assembler: the appliance file read into a ``Config`` from every registered table (the
appliance's own, each sensor's, each publisher's), and the checks made before the daemon starts."""
