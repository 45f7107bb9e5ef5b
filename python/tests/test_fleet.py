"""The fleet (jointid.fleet): a small simulated fleet with planted drift run night by night
on the local engine and on a local Ray instance; the same rows either way, every planted
drift flagged on the night it starts, no unchanged joint flagged; a night killed half-way
and resumed; a finished night replaced alone; bad manifests and captures reported."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

duckdb = pytest.importorskip("duckdb", reason="the fleet needs duckdb (python/ci.sh installs it)")
pytest.importorskip("pyarrow", reason="the fleet needs pyarrow (python/ci.sh installs it)")

from jointid import fleet  # noqa: E402

NIGHTS = ["2026-12-01", "2026-12-02", "2026-12-03"]


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    """20 joints (5 robots × 4) × 3 nights, half of them drifting, written once."""
    d = tmp_path_factory.mktemp("fleet")
    truth = fleet.simulate_fleet(5, 4, 3, d / "sim", seed=7)
    return d, truth


@pytest.fixture(scope="module")
def local_results(sim):
    d, _ = sim
    out = d / "local"
    for night in NIGHTS:
        s = fleet.run(d / "sim" / f"manifest-{night}.csv", out, workers=2)
        assert s.nights[night]["failed"] == 0, s.to_dict()
    return out


def _rows(out):
    con = duckdb.connect()
    return con.execute(
        f"SELECT * EXCLUDE (cpu_s, wall_s, engine) FROM read_parquet('{Path(out).as_posix()}/date=*/*.parquet', "
        "hive_partitioning = true) ORDER BY robot, joint, taken_at"
    ).fetchall()


def test_every_planted_drift_is_flagged_on_its_night_and_no_unchanged_joint(sim, local_results):
    _, truth = sim
    rep = fleet.drift(local_results)
    flagged = {(j["robot"], j["joint"]): j for j in rep["joints"] if j["flagged"]}
    drifting = {(j["robot"], j["joint"]): j for j in truth["joints"] if j["drift"] != "none"}
    assert set(flagged) == set(drifting), fleet.drift_table(rep, all_joints=True)
    for key, j in drifting.items():
        first = min(m["first_night"] for m in flagged[key]["moved"])
        if j["drift"] in ("friction", "stiffness"):
            # a parameter's drift: flagged on the night it starts
            assert first == j["shows_from"], (key, j["drift"], flagged[key]["moved"])
        else:
            # an effect's (backlash, mode): the linear fit moves, on that night or the next
            # as it grows; the diagnosis names it on its night (the test below)
            assert first >= j["shows_from"], (key, j["drift"], flagged[key]["moved"])
        # the planted parameter is the one that moved
        moved = {m["name"] for m in flagged[key]["moved"]}
        if j["drift"] == "friction":
            assert "f_m" in moved, moved
        if j["drift"] == "stiffness":
            assert "k_g" in moved, moved
            k = next(m for m in flagged[key]["moved"] if m["name"] == "k_g")
            assert k["change"] == pytest.approx(-0.30, abs=0.03), k
    # the dataset read back: one row per joint and night, every parameter with σ and unit
    rows = _rows(local_results)
    assert len(rows) == len(truth["joints"]) * len(NIGHTS)
    con = duckdb.connect()
    n, bad = con.execute(
        f"SELECT count(*), count(*) FILTER (WHERE p.std IS NULL OR p.unit IS NULL) FROM "
        f"(SELECT unnest(params) AS p FROM read_parquet('{local_results.as_posix()}/date=*/*.parquet'))"
    ).fetchone()
    assert n >= 8 * len(rows) and bad == 0


def test_ray_gives_the_same_rows_as_the_local_engine(sim, local_results):
    pytest.importorskip("ray", reason="the Ray engine needs ray (python/ci.sh installs it)")
    d, _ = sim
    out = d / "ray"
    for night in NIGHTS:
        s = fleet.run(d / "sim" / f"manifest-{night}.csv", out, engine="ray", workers=2)
        assert s.engine == "ray" and s.nights[night]["run"] == 20
    assert _rows(out) == _rows(local_results)
    con = duckdb.connect()
    engines = con.execute(
        f"SELECT DISTINCT engine FROM read_parquet('{out.as_posix()}/date=*/*.parquet')"
    ).fetchall()
    assert engines == [("ray",)]


def test_a_night_killed_half_way_resumes_and_a_finished_night_is_replaced_alone(sim, tmp_path):
    d, truth = sim
    out = tmp_path / "res"
    first = d / "sim" / f"manifest-{NIGHTS[0]}.csv"
    fleet.run(first, out, workers=2)
    other = out / f"date={NIGHTS[0]}"
    other_parts = {p.name: p.stat().st_mtime_ns for p in other.iterdir()}
    night = NIGHTS[1]
    part = out / f"date={night}"
    cmd = [sys.executable, "-m", "jointid.fleet", "run", str(d / "sim" / f"manifest-{night}.csv"),
           "--out", str(out), "--workers", "1"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    t0 = time.monotonic()
    while not (part / "part-00000.parquet").exists():
        assert proc.poll() is None, "the run ended before writing its first part"
        assert time.monotonic() - t0 < 300, "no part written within 300 s"
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert not (part / fleet.DONE).exists()
    written = len(_rows(out)) - 20
    assert 0 < written < 20
    s = fleet.run(d / "sim" / f"manifest-{night}.csv", out, workers=2)
    assert s.nights[night]["resumed"] == written and s.nights[night]["run"] == 20 - written
    assert not s.nights[night]["replaced"]
    rows = _rows(out)
    keys = [(r[0], r[1], r[2]) for r in rows]
    assert len(keys) == len(set(keys)) == 40
    # a finished night run again is replaced, the other night left as it was
    s = fleet.run(d / "sim" / f"manifest-{night}.csv", out, workers=2)
    assert s.nights[night]["replaced"] and s.nights[night]["run"] == 20
    assert len(_rows(out)) == 40
    assert {p.name: p.stat().st_mtime_ns for p in other.iterdir()} == other_parts


def test_a_bad_capture_is_a_row_with_its_error_and_the_night_goes_on(sim, tmp_path):
    d, _ = sim
    src = d / "sim" / f"manifest-{NIGHTS[0]}.csv"
    lines = src.read_text().splitlines()
    # the third joint's capture replaced by a file that is no capture
    bad = tmp_path / "broken.csv"
    bad.write_text("t,u\n0,x\n")
    cols = lines[2].split(",")
    cols[3] = str(bad)
    cols[4] = ""
    lines[2] = ",".join(cols)
    for i in range(1, len(lines)):
        c = lines[i].split(",")
        for k in (3, 4):
            if c[k] and not os.path.isabs(c[k]):
                c[k] = str(d / "sim" / c[k])
        lines[i] = ",".join(c)
    m = tmp_path / "manifest.csv"
    m.write_text("\n".join(lines[:5]) + "\n")
    r = subprocess.run([sys.executable, "-m", "jointid.fleet", "run", str(m), "--out", str(tmp_path / "o"), "--json"],
                       capture_output=True, text=True)
    assert r.returncode == 1, r.stderr
    summary = json.loads(r.stdout)
    assert summary["nights"][NIGHTS[0]]["failed"] == 1
    con = duckdb.connect()
    st = con.execute(
        f"SELECT status, error FROM read_parquet('{(tmp_path / 'o').as_posix()}/date=*/*.parquet') ORDER BY status"
    ).fetchall()
    assert [s for s, _ in st].count("ok") == 3
    err = [e for s, e in st if s == "error"][0]
    assert "broken.csv" in err, err


@pytest.mark.parametrize(
    "text,says",
    [
        ("robot,joint,capture\nr1,j1,a.jcap\n", "lacks the column(s) taken_at"),
        ("robot,joint,taken_at,capture\nr1,j1,yesterday,a.jcap\n", "line 2: taken_at 'yesterday'"),
        ("robot,joint,taken_at,capture\nr1,j1,2026-12-01,a.jcap\nr1,j1,2026-12-01,b.jcap\n",
         "line 3: robot r1 joint j1 taken at 2026-12-01 is already on line 2"),
        ("robot,joint,taken_at,capture\nr1,,2026-12-01,a.jcap\n", "line 2: column joint is empty"),
    ],
)
def test_a_bad_manifest_is_refused_naming_its_file_and_line(tmp_path, text, says):
    m = tmp_path / "m.csv"
    m.write_text(text)
    with pytest.raises(fleet.FleetError) as e:
        fleet.read_manifest(m)
    assert str(m) in str(e.value) and says in str(e.value)


def test_the_drift_page_shows_one_row_and_a_trend_plot_per_flagged_joint(local_results, tmp_path):
    rep = fleet.drift(local_results)
    page = tmp_path / "drift.html"
    page.write_text(fleet.drift_html(rep))
    n = sum(j["flagged"] for j in rep["joints"])
    chromium = shutil.which("chromium")
    if chromium is None:
        pytest.fail("chromium is not installed: run .ci/setup (it installs Debian's `chromium`)")
    r = subprocess.run(
        [chromium, "--headless=new", "--no-sandbox", "--disable-gpu",
         f"--user-data-dir={tmp_path / 'profile'}", "--dump-dom", page.as_uri()],
        capture_output=True, text=True, timeout=120,
    )
    dom = r.stdout
    assert dom.count('<tr class="flagged"') == n, r.stderr[-2000:]
    assert dom.count("<svg") >= n
    assert f"{n} of {len(rep['joints'])} joints flagged" in dom


def test_two_shards_write_the_rows_one_run_writes(sim, local_results, tmp_path):
    d, _ = sim
    out = tmp_path / "sharded"
    night = NIGHTS[0]
    for k in (0, 1):
        s = fleet.run(d / "sim" / f"manifest-{night}.csv", out, workers=1, shard=(k, 2))
        assert s.nights[night]["run"] == 10
    names = sorted(p.name for p in (out / f"date={night}").iterdir())
    assert fleet.DONE + "-0-of-2" in names and fleet.DONE + "-1-of-2" in names
    mine = [r for r in _rows(local_results) if r[2].startswith(night)]
    assert _rows(out) == mine


def test_an_effect_that_appears_is_named_by_the_diagnosis_on_its_night(tmp_path):
    """Two joints, two nights, with the diagnosis: a backlash opens on the second night of
    one of them; the other stays as it was."""
    truth = fleet.simulate_fleet(2, 1, 2, tmp_path / "sim", seed=5, kinds=["backlash"])
    assert [j["drift"] for j in truth["joints"]] == ["backlash", "none"]
    for night in NIGHTS[:2]:
        s = fleet.run(tmp_path / "sim" / f"manifest-{night}.csv", tmp_path / "res", diagnose=True, workers=2)
        assert s.nights[night]["failed"] == 0
    rep = fleet.drift(tmp_path / "res")
    by = {j["robot"]: j for j in rep["joints"]}
    assert not by["r002"]["flagged"], fleet.drift_table(rep, all_joints=True)
    effects = by["r001"]["effects"]
    assert effects and effects[0]["kind"] == "appeared" and effects[0]["night"] == NIGHTS[1], effects
    assert "backlash" in effects[0]["to"].split("+"), effects
