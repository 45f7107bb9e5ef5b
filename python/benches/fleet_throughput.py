"""Fleet throughput on this machine: joints per CPU-hour for the fit alone and for the fit
with the diagnosis, on the local engine and through a local Ray instance, and Ray's
overhead per task. Prints the figures; writes nothing outside a temporary directory.

    python python/benches/fleet_throughput.py [--joints 16] [--diagnosed 4] [--workers 2]

CPU is the joints' own (each worker's process time, summed); wall is the run's. A joint is
one four-period capture of a simulated three-mass joint (24,000 samples at 2 kHz, about
70 kB as .jcap) with a validation capture of the same length.
"""

import argparse
import tempfile
import time
from pathlib import Path

from jointid import fleet


def once(manifest, out, **kw):
    t0 = time.perf_counter()
    s = fleet.run(manifest, out, **kw)
    wall = time.perf_counter() - t0
    n = sum(v["run"] for v in s.nights.values())
    failed = sum(v["failed"] for v in s.nights.values())
    return n, failed, s.cpu_s, wall


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--joints", type=int, default=16)
    ap.add_argument("--diagnosed", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        d = Path(d)
        fleet.simulate_fleet(a.joints, 1, 1, d / "sim", seed=3, drifting=0)
        rows = (d / "sim" / "manifest.csv").read_text().splitlines()
        small = d / "sim" / "diagnosed.csv"
        small.write_text("\n".join(rows[: a.diagnosed + 1]) + "\n")
        print(f"fleet throughput: {a.joints} joints fitted, {a.diagnosed} diagnosed, {a.workers} workers")
        print(f"{'what':<28} {'engine':<6} {'joints':>6} {'CPU s/joint':>12} {'joints/CPU-h':>13} {'wall s':>8} {'wall s/joint':>13}")
        res = {}
        for label, manifest, diag in (("fit", d / "sim" / "manifest.csv", False), ("fit + diagnosis", small, True)):
            for engine in ("local", "ray"):
                n, failed, cpu, wall = once(manifest, d / f"out-{engine}-{diag}", diagnose=diag, engine=engine, workers=a.workers)
                res[(label, engine)] = (n, cpu, wall)
                print(f"{label:<28} {engine:<6} {n:>6} {cpu / n:>12.2f} {3600 * n / cpu:>13.0f} {wall:>8.1f} {wall / n:>13.2f}"
                      + (f"  ({failed} failed)" if failed else ""))
        for label in ("fit", "fit + diagnosis"):
            n, _, wl = res[(label, "local")]
            _, _, wr = res[(label, "ray")]
            print(f"Ray overhead, {label}: {(wr - wl) / n:+.2f} s wall per joint on {a.workers} workers "
                  f"(the instance's start included)")
        n, cpu, _ = res[("fit + diagnosis", "local")]
        per = cpu / n
        print(f"a night of 10,000 joints with the diagnosis: {10000 * per / 3600:.0f} CPU-hours "
              f"({per:.1f} s per joint); in 8 hours: {10000 * per / 3600 / 8:.0f} cores")
        n, cpu, _ = res[("fit", "local")]
        print(f"a night of 10,000 joints, fit only: {10000 * cpu / n / 3600:.1f} CPU-hours")


if __name__ == "__main__":
    main()
