"""moi measurement core: pure, hardware-free science (numpy, scipy, opencv only).

Public entry points:

    Rig, Trace, parse_trace_csv         inputs
    Pendulum, simulate_trace, Swing     simulation (truth for tests and mocks)
    identify, Options                   whole-record identification + discovery
    IdentificationResult                the result object every output is made from
    calibrate_torsion                   stiffness and tare from reference loads
"""

from .effects import EFFECTS, Effect, Parameter
from .errors import InvalidInput, MeasurementError
from .identification import Options, identify
from .result import IdentificationResult, Quantity
from .rig import Rig
from .simulate import Pendulum, Swing, quantise, simulate_trace
from .trace import Trace, parse_trace_csv

__all__ = [
    "EFFECTS", "Effect", "Parameter", "InvalidInput", "MeasurementError", "Options", "identify",
    "IdentificationResult", "Quantity", "Rig", "Pendulum", "Swing", "quantise", "simulate_trace",
    "Trace", "parse_trace_csv",
]
