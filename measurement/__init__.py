"""moi measurement core: pure, hardware-free science (numpy, scipy, opencv only).

Public entry points:

    Rig, Trace, parse_trace_csv         inputs
    Pendulum, simulate_trace, Swing     simulation (truth for tests and mocks)
    identify, Options                   whole-record identification + discovery
    IdentificationResult                the result object every output is made from
    calibrate_torsion                   stiffness and tare from reference loads
"""

from typing import TYPE_CHECKING

from ._lazy import lazy_exports

#: public name → the submodule that defines it. Imported on first use (PEP 562), so that
#: ``import measurement.errors`` or ``measurement.rig`` does not load scipy: commands that do
#: not identify (``moi --help``, ``moi results``...) start without it.
_WHERE = {
    "EFFECTS": "effects", "Effect": "effect_base", "Parameter": "effect_base",
    "InvalidInput": "errors", "MeasurementError": "errors",
    "Options": "identification", "identify": "identification",
    "IdentificationResult": "result", "Quantity": "result",
    "Rig": "rig",
    "Pendulum": "simulate", "Swing": "simulate", "quantise": "simulate", "simulate_trace": "simulate",
    "Trace": "trace", "parse_trace_csv": "trace",
}


__getattr__, __dir__ = lazy_exports(__name__, globals(), _WHERE)


if TYPE_CHECKING:  # pragma: no cover
    from .effect_base import Effect, Parameter
    from .effects import EFFECTS
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
