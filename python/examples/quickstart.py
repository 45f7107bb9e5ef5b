"""The README's path from Python: a capture, its FRF, a three-mass fit checked on a second
capture, the model's matrices and the sim-to-real diagnosis.

    python examples/quickstart.py [DIR]     # files go to DIR (default: a temporary one)

With a board, `jointid capture ... --out run.jcap` records the captures; here the
simulated IRB1400-like joint writes them, as `jointid simulate` does.
"""

import os
import sys
import tempfile

import numpy as np

import jointid

workdir = sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp(prefix="jointid-quickstart-")
os.makedirs(workdir, exist_ok=True)
os.chdir(workdir)

# two captures of the simulated joint (estimation and validation), 4 periods each
jointid.simulate("run.jcap", model="three-mass", periods=4, seed=1, force=True)
jointid.simulate("val.jcap", model="three-mass", periods=4, seed=2, force=True)

df = jointid.read_capture("run.jcap")
print(f"{len(df)} samples at {1 / df.attrs['ts']:.0f} Hz, excitation period "
      f"{df.attrs['excitation']['period_samples']} samples, gaps: {df.attrs['gaps']}")

a = jointid.analyze("run.jcap")
print(f"FRF on {len(a.freq_hz)} excited lines ({a.freq_hz[0]} to {a.freq_hz[-1]} Hz); "
      f"distortion detected: {a.distortion_detected}")

m = jointid.fit("run.jcap", model="three-mass", validation="val.jcap")
for name, p in m.parameters.items():
    print(f"  {name:<6} {p.value:12.5g} ± {p.std:.2g} {p.unit}")
print(f"FIT estimation {m.fit_estimation:.2f} %, validation {m.fit_validation:.2f} %, "
      f"resonances {np.round(m.resonances_hz, 2)} Hz")

A, B, C, D = m.state_space()                 # discrete, at m.ts_model
F, G, H, _ = m.state_space(continuous=True)  # ẋ = F x + G u, y = H x + D u
print(f"state space: {A.shape[0]} states, max |eig(A)| {np.abs(np.linalg.eigvals(A)).max():.6f}")

d = jointid.diagnose("run.jcap", validation="val.jcap", model="three-mass", effects="backlash")
print(f"diagnosis: best candidate {d.best}")
print(f"m.to_dict() is `jointid fit run.jcap --model three-mass --validation val.jcap --json` "
      f"({len(m.to_dict())} fields); files in {workdir}")
