"""Write the simulated traces of bracket.toml: the example bracket (measurement.simulate.BRACKET) mounted
on examples/torsion_rig.toml in each orientation of the plan, 10 s at 50 Hz, 0.3 mrad noise.

Run from the repository: `.venv/bin/python examples/tensor/make_traces.py`.
"""

import tomllib
from pathlib import Path

from measurement.simulate import BRACKET, simulate_set
from measurement.tensor import TensorPlan
from service.sources.files import read_rig, write_text_atomic

HERE = Path(__file__).resolve().parent


def main() -> None:
    doc = tomllib.loads((HERE / "bracket.toml").read_text())
    plan = TensorPlan.from_dict(doc, extra_orientation_keys=("traces",), extra_keys=("rig",))
    rig = read_rig(HERE / doc["rig"])
    releases = max(len(o["traces"]) for o in doc["orientation"])
    sets = simulate_set(BRACKET, rig, plan, releases=releases, seed=2, duration=10.0, rate=50.0)
    for row, traces in zip(doc["orientation"], sets):
        for name, trace in zip(row["traces"], traces):
            comment = (f"simulated by examples/tensor/make_traces.py: the example bracket about axis {row['axis']}"
                       f" (offset {row.get('offset', [0, 0, 0])} m) on examples/torsion_rig.toml")
            write_text_atomic(HERE / name, trace.to_csv(comment))


if __name__ == "__main__":
    main()
