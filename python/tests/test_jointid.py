"""The package against the simulated truth and against the command line it wraps."""

import json
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import jointid


def run_cli(cli, *args):
    """`jointid --json ARGS`: (document, exit code)."""
    p = subprocess.run([cli, "--json", *map(str, args)], capture_output=True, text=True)
    return json.loads(p.stdout), p.returncode


def without_timing(doc):
    doc = dict(doc)
    doc.pop("elapsed_s", None)
    doc.pop("seconds", None)
    return doc


def test_read_capture_columns_and_attributes(captures):
    est = captures["est"]
    df = jointid.read_capture(est.path)
    assert isinstance(df, pd.DataFrame)
    assert list(df.columns) == ["t", "theta_ref", "u", "theta_m", "segment"]
    assert len(df) == est.samples == 24000
    a = df.attrs
    assert a["ts"] == pytest.approx(5e-4)
    assert np.allclose(np.diff(df["t"]), 5e-4)
    assert a["excitation"]["period_samples"] == 5000
    assert a["excitation"]["periods"] == 4
    assert a["gaps"] == []
    assert [s["samples"] for s in a["segments"]] == [24000]
    assert (df["segment"] == 1).all()
    # the reference is the excitation: rms 0.02 rad at full amplitude (after the ramp)
    steady = df["theta_ref"].to_numpy()[2000:22000]
    assert np.sqrt(np.mean(steady**2)) == pytest.approx(0.02, rel=0.02)


def test_a_gap_written_and_read_back(captures, tmp_path):
    df = jointid.read_capture(captures["est"].path)
    cut = df.drop(index=range(3000, 3100))
    jointid.write_capture(cut, tmp_path / "gap.csv")
    back = jointid.read_capture(tmp_path / "gap.csv")
    assert [s["samples"] for s in back.attrs["segments"]] == [3000, 20900]
    (gap,) = back.attrs["gaps"]
    assert gap["after_segment"] == 1 and gap["samples"] == 100
    assert gap["start_s"] == pytest.approx(1.5) and gap["end_s"] == pytest.approx(1.55)
    assert np.array_equal(back["u"].to_numpy(), cut["u"].to_numpy())
    assert back["segment"].tolist() == [1] * 3000 + [2] * 20900


def test_fit_reaches_the_simulated_truth(captures):
    truth = captures["est"].config["plant"]["params"]
    f = jointid.fit(captures["est"].path, model="three-mass", validation=captures["val"].path)
    names = ["J_m", "J_a1", "J_a2", "k_g", "k_a", "d_g", "d_a", "f_m"]
    assert sorted(n for n in f.parameters if n in truth) == sorted(names)
    for n in names:
        p = f.parameters[n]
        assert abs(p.value - truth[n]) < 3 * p.std, (n, p, truth[n])
    assert f.parameters["k_g"].unit == "N·m/rad"
    assert f.fit_estimation > 95 and f.fit_validation > 95
    # the simulated joint's resonances (simulate reports them from the true parameters)
    assert np.allclose(f.resonances_hz, captures["est"].resonances_hz, rtol=0.01)


def test_to_dict_is_fit_json(captures, cli):
    est, val = captures["est"].path, captures["val"].path
    f = jointid.fit(est, model="three-mass", validation=val, current_loop_tau=4e-4)
    doc, code = run_cli(cli, "fit", est, "--model", "three-mass", "--validation", val,
                        "--current-loop-tau", "0.0004")
    assert code == 0
    assert without_timing(f.to_dict()) == without_timing(doc)
    assert f.to_dict()["schema"] == "jointid-fit/1"


def test_simulate_and_analyze_dicts_are_the_commands_json(captures, cli, tmp_path):
    s = jointid.simulate(tmp_path / "p.jcap", model="two-mass", periods=3, seed=5)
    doc, code = run_cli(cli, "simulate", "--out", tmp_path / "c.jcap", "--model", "two-mass",
                        "--periods", 3, "--seed", 5)
    assert code == 0
    mine, theirs = s.to_dict(), doc
    assert mine.pop("out").endswith("p.jcap") and theirs.pop("out").endswith("c.jcap")
    assert mine == theirs
    assert (tmp_path / "p.jcap").read_bytes() == (tmp_path / "c.jcap").read_bytes()

    a = jointid.analyze(captures["est"].path)
    doc, code = run_cli(cli, "analyze", captures["est"].path)
    assert code == 0 and a.to_dict() == doc
    # the FRF at the excited lines: f0 = fs / N = 0.4 Hz, low-frequency gain of a rigid
    # body 1 / (J ω²) with J the motor plus the arm inertia seen through the gear
    assert a.freq_hz[0] == pytest.approx(0.4)
    assert a.frf.dtype == complex and a.frf.shape == a.freq_hz.shape == a.frf_sigma.shape
    assert not a.distortion_detected


def test_state_space_shapes_stability_and_resonances(captures):
    f = jointid.fit(captures["est"].path, model="three-mass")
    A, B, C, D = f.state_space()
    n = A.shape[0]
    assert A.shape == (n, n) and B.shape == (n, 1) and C.shape == (1, n) and D.shape == (1, 1)
    assert f.ts_model == pytest.approx(5e-4)
    assert np.abs(np.linalg.eigvals(A)).max() <= 1 + 1e-9
    F, G, H, Dc = f.state_space(continuous=True)
    assert F.shape == (n, n) and G.shape == (n, 1) and H.shape == (1, n)
    s = np.linalg.eigvals(F)
    assert s.real.max() <= 1e-9
    # each reported resonance is the undamped frequency of a lightly damped pole pair
    for r in f.resonances_hz:
        assert np.min(np.abs(np.abs(s) / (2 * np.pi) - r)) < 1e-6 * r
    # the continuous and the discrete model agree at low frequency (zero-order hold)
    w = 2 * np.pi * 2.0
    gc = (H @ np.linalg.solve(1j * w * np.eye(n) - F, G))[0, 0] + Dc[0, 0]
    z = np.exp(1j * w * f.ts_model)
    gd = (C @ np.linalg.solve(z * np.eye(n) - A, B))[0, 0] + D[0, 0]
    assert abs(gd / gc - 1) < 0.01


def test_black_box_has_no_continuous_form(captures):
    f = jointid.fit(captures["est"].path, model="black-box:6", no_refine=True)
    assert f.state_space()[0].shape == (6, 6)
    with pytest.raises(jointid.JointidError, match="no continuous model"):
        f.state_space(continuous=True)


def test_fit_of_a_dataframe_is_the_fit_of_its_file(captures):
    path = captures["est"].path
    a = jointid.fit(path, model="three-mass")
    b = jointid.fit(jointid.read_capture(path), model="three-mass")
    assert b.parameters == a.parameters
    assert b.fit_estimation == a.fit_estimation


def test_errors_carry_the_command_lines_message(captures, cli, tmp_path):
    missing = tmp_path / "nowhere.jcap"
    with pytest.raises(jointid.JointidError) as e:
        jointid.fit(missing, model="three-mass")
    assert str(missing) in str(e.value)
    doc, code = run_cli(cli, "fit", missing, "--model", "three-mass")
    assert code == 2 and doc["error"] == str(e.value)

    with pytest.raises(jointid.JointidError) as e:
        jointid.fit(captures["est"].path, model="five-mass")
    doc, code = run_cli(cli, "fit", captures["est"].path, "--model", "five-mass")
    assert code == 2 and doc["error"] == str(e.value)
    assert "unknown model `five-mass`" in str(e.value)

    with pytest.raises(jointid.JointidError, match="lacks column"):
        jointid.fit(pd.DataFrame({"t": [0.0, 1.0]}), model="rigid")
    with pytest.raises(jointid.JointidError, match="exists"):
        jointid.simulate(captures["est"].path, periods=2)


def test_diagnose_is_the_commands_json(captures, cli):
    est, val = captures["est"].path, captures["val"].path
    d = jointid.diagnose(est, validation=val, model="three-mass", effects="backlash")
    doc, code = run_cli(cli, "diagnose", est, "--validation", val, "--model", "three-mass",
                        "--effects", "backlash")
    assert code == 0
    assert without_timing(d.to_dict()) == without_timing(doc)
    # the simulated joint is the nominal three-mass: backlash does not count
    assert d.best == "none"
    assert [(e["name"], e["significant"]) for e in d.effects] == [("backlash", False)]


def test_the_readmes_python_lines(tmp_path, monkeypatch):
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    section = readme.split("\n## Python\n", 1)[1].split("\n## ", 1)[0]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(tmp_path)
    scope = {}
    exec(compile(code, "README.md (Python)", "exec"), scope)
    m = scope["m"]
    assert isinstance(m, jointid.FitResult) and m.fit_validation > 95
    assert scope["A"].shape == (7, 7)
    assert list(scope["df"].columns)[:4] == ["t", "theta_ref", "u", "theta_m"]


def test_read_capture_of_a_mapped_csv(tmp_path):
    path = tmp_path / "drive.csv"
    t = np.arange(400) * 1e-3
    path.write_text("time_s,force,pos\n" + "".join(
        f"{float(a)!r},{float(np.sin(a))!r},{float(np.cos(a))!r}\n" for a in t))
    df = jointid.read_capture(path, time="time_s", input="force", output="pos")
    assert list(df.columns) == ["t", "u", "theta_m", "segment"]
    assert df.attrs["ts"] == pytest.approx(1e-3) and df.attrs["excitation"] is None
    assert np.array_equal(df["u"].to_numpy(), np.sin(t))
    with pytest.raises(jointid.JointidError, match="give all three"):
        jointid.read_capture(path, time="time_s")
    with pytest.raises(jointid.JointidError, match="nope"):
        jointid.read_capture(path, time="time_s", input="nope", output="pos")
