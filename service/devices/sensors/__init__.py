"""The angle sensors: one module each (``port``: the interface), listed in ``registry``."""
