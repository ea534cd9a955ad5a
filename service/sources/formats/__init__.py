"""Readers of the files people export (phyphox, Tracker, Logger Pro, PASCO Capstone, any CSV/TSV): one
module per format, listed in ``registry.py``, each turning a file into a ``Log`` (its columns, their
units, its events); ``reading.py`` turns a log into the traces of its releases."""
