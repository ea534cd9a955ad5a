"""`make bench`: run every bench/bench_*.py and print what each measures.

Speed goals are measured here, never asserted in tests.
"""

import importlib.util
import pathlib
import sys
import time

HERE = pathlib.Path(__file__).resolve().parent


def main() -> int:
    sys.path.insert(0, str(HERE.parent))
    sys.path.insert(1, str(HERE))  # the benches' shared helpers (bench_startup, _appliance)
    failures = 0
    for path in sorted(HERE.glob("bench_*.py")):
        print(f"=== {path.name}")
        spec = importlib.util.spec_from_file_location(path.stem, path)
        # a .py path always gets a spec with the source loader; None is for suffixes no loader knows
        assert spec is not None and spec.loader is not None, path
        module = importlib.util.module_from_spec(spec)
        # registered under its name: a bench that hands its functions to worker
        # processes (bench_discovery_power) pickles them by module and name
        sys.modules[path.stem] = module
        t0 = time.perf_counter()
        try:
            spec.loader.exec_module(module)
            module.main()
        except Exception as exc:  # a broken bench must not hide the others
            failures += 1
            print(f"!!! {path.name} failed: {exc!r}")
        print(f"--- {path.name}: {time.perf_counter() - t0:.1f} s\n")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
