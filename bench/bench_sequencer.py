"""Sequencer: time from the end of the capture to the result, and how responsive poll() stays meanwhile.

Two set-ups on the simulated rig (torsion, J = 0.0125 kg·m², viscous + Coulomb,
θ0 = 0.25 rad, 30 s capture):

    modbus   the simulated encoder server read by the Modbus client as fast as the
             loopback bus allows (many samples), clock × 5
    200 Hz   an in-process sensor at 200 Hz, 17 bits (the trace size the
             identification is specified for), clock × 50

capture→result is wall time from the IDENTIFYING event (capture over) to the
PUBLISHING event (result in the sink). max poll is the longest single
``poll()`` call while identifying: what the daemon's watchdog loop waits at most.
"""

from __future__ import annotations

import logging
import time


def one(kind: str, seed: int) -> dict:
    from gpiozero.pins.mock import MockFactory

    from drivers.clock import ScaledClock
    from drivers.sensor import AngleSensor, SimulatedAngleSensor
    from drivers.simrig import SimRig
    from drivers.solenoid import Solenoid
    from firmware_host import Event, Measurement, Sequencer, SequencerConfig, State
    from measurement import Pendulum, Rig

    rig = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
    truth = Pendulum(rig, 0.0125, {"viscous": {"c": 1.5e-4}, "coulomb": {"Tc": 1.2e-4}})
    clock = ScaledClock(5.0 if kind == "modbus" else 50.0)
    factory = MockFactory()
    closers = []
    solenoid = Solenoid(17, max_on_time=0.5, pin_factory=factory)
    closers.append(solenoid.close)
    sim = SimRig(truth, theta0=0.25, clock=clock, duration=40.0).attach(solenoid)
    sensor: AngleSensor
    if kind == "modbus":
        from drivers.encoder import ModbusEncoder
        from drivers.sim_encoder import SimEncoderConfig, SimEncoderServer
        server = SimEncoderServer(sim.angle, clock, SimEncoderConfig(latency=0.0002, seed=seed)).start()
        closers.append(server.stop)
        sensor = ModbusEncoder(server.encoder_config(timeout=0.02), clock)
    else:
        sensor = SimulatedAngleSensor(sim.angle, clock, rate=200.0, quantisation_bits=17, seed=seed)
    closers.append(sensor.close)
    marks: dict[str, float] = {}
    results: list[Measurement] = []
    seq = Sequencer(clock=clock, solenoid=solenoid, sensor=sensor, rig=rig, sink=results.append,
                    config=SequencerConfig(capture_duration=30.0, sample_timeout=5.0))

    def mark(event: Event) -> None:  # wall time of each state's first entry
        marks.setdefault(event.state.value, time.perf_counter())

    seq.subscribe(mark)
    max_poll = 0.0
    try:
        seq.request_measurement("bench")
        while True:
            t0 = time.perf_counter()
            state = seq.poll()
            dt = time.perf_counter() - t0
            if state is State.IDENTIFYING:
                max_poll = max(max_poll, dt)
            if state in (State.IDLE, State.FAULT) and not seq.busy:
                break
            clock.sleep(0.01)
    finally:
        seq.close()
        for close in reversed(closers):
            close()
    if not results:
        raise RuntimeError(f"{kind}: no result: {seq.last_fault}")
    m = results[0]
    assert m.result.J is not None, "the torsion rig gives the stiffness: J is known"
    return {"kind": kind, "samples": len(m.trace), "capture_to_result": marks["PUBLISHING"] - marks["IDENTIFYING"],
            "max_poll_ms": 1e3 * max_poll, "J_error_pct": 100 * (m.result.J / truth.inertia - 1),
            "added": ",".join(m.result.added_effects) or "-"}


def main() -> None:
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    for kind in ("200 Hz", "modbus"):
        rows = [one(kind, seed) for seed in (1, 2, 3)]
        for r in rows:
            print(f"{r['kind']:>7}: {r['samples']:6d} samples, capture→result {r['capture_to_result']:5.2f} s, "
                  f"max poll() while identifying {r['max_poll_ms']:.2f} ms, J error {r['J_error_pct']:+.4f} %, "
                  f"added {r['added']}")


if __name__ == "__main__":
    main()
