"""A fleet of joints, every night: re-identification and drift diagnosis of many joints.

``run`` fits each joint a manifest names (and, with ``diagnose=True``, diagnoses its gap
against the joint's previous model) and writes one row per joint to a Hive-partitioned
Parquet dataset, ``OUT/date=YYYY-MM-DD/part-NNNNN.parquet``. ``drift`` reads the dataset
back through DuckDB and lists, per joint, the parameters that moved, the effects that
appeared and the validation FIT's trend. ``simulate_fleet`` writes a fleet of simulated
joints with planted drift and its truth, to test on.

Engines: ``"local"`` (the default) runs the joints in a process pool on this machine's
cores, no service to start; ``"ray"`` runs each joint as a Ray task, on a local Ray
instance started for the run or on the cluster at ``ray_address``. The rows are the same
either way (only ``engine``, ``cpu_s`` and ``wall_s`` differ). Retries, placement and
back-pressure are Ray's; this module only submits the joints and writes what comes back.

The fleet lives in Python because Ray's task API is Python's: a joint is one call of this
package's ``fit``/``diagnose`` (the Rust library in-process), which a Ray worker runs as
it is; the command line ``python -m jointid.fleet`` (or ``jointid-fleet``) is a thin
wrapper over these functions.

Needs ``pyarrow`` and ``duckdb`` (``pip install jointid[fleet]``), and ``ray`` for the Ray
engine (``pip install jointid[ray]``).
"""

from __future__ import annotations

import argparse
import csv
import datetime as _dt
import html
import json
import math
import os
import shutil
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator

__all__ = [
    "FleetError",
    "RunSummary",
    "read_manifest",
    "run",
    "drift",
    "drift_html",
    "simulate_fleet",
    "main",
]

#: columns every manifest row needs
REQUIRED = ("robot", "joint", "taken_at", "capture")
#: columns a manifest row may give: a validation capture, the structure to fit (default
#: three-mass), the joint's previous model (a ``fit --save`` or ``simulate --params-out``
#: file, the diagnosis's reference)
OPTIONAL = ("validation", "structure", "model_file")
#: results written per Parquet part: a run killed half-way loses at most this many joints'
#: work, and resumes from the parts already written
CHUNK = 8
#: the marker of a night whose run finished; a night without it is resumed, one with it is
#: replaced by a new run
DONE = "_SUCCESS"


class FleetError(Exception):
    """A manifest, a results directory or an option the fleet cannot use; the message names
    the file, the line or the column and what was expected."""


# --- the manifest -------------------------------------------------------------------


def read_manifest(path) -> list[dict]:
    """The joints of the manifest ``path`` (CSV with a header, or Parquet): one dict per row
    with the columns of :data:`REQUIRED` and :data:`OPTIONAL` (``None`` when not given),
    capture paths made absolute against the manifest's directory and ``night`` the date of
    ``taken_at``. Raises :class:`FleetError` naming the file, the line and the column."""
    path = Path(path)
    if not path.is_file():
        raise FleetError(f"{path}: no such manifest")
    if path.suffix.lower() == ".parquet":
        import pyarrow.parquet as pq

        table = pq.read_table(path)
        names = table.column_names
        raw = table.to_pylist()
        first_line = 1
    else:
        with open(path, newline="", encoding="utf-8") as f:
            reader = csv.DictReader(f)
            names = reader.fieldnames or []
            raw = list(reader)
        first_line = 2
    missing = [c for c in REQUIRED if c not in names]
    if missing:
        raise FleetError(
            f"{path}: the manifest lacks the column(s) {', '.join(missing)} "
            f"(needs {', '.join(REQUIRED)}; may give {', '.join(OPTIONAL)})"
        )
    rows = []
    seen: dict[tuple, int] = {}
    for i, r in enumerate(raw):
        line = i + first_line
        row = {c: _text(r.get(c)) for c in REQUIRED + OPTIONAL}
        for c in REQUIRED:
            if not row[c]:
                raise FleetError(f"{path}, line {line}: column {c} is empty")
        try:
            taken = _dt.datetime.fromisoformat(row["taken_at"])
        except ValueError:
            raise FleetError(
                f"{path}, line {line}: taken_at {row['taken_at']!r} is not an ISO date or "
                "date-time (2026-12-01 or 2026-12-01T02:30:00)"
            ) from None
        row["night"] = taken.date().isoformat()
        for c in ("capture", "validation", "model_file"):
            if row[c]:
                p = Path(row[c])
                row[c] = str(p if p.is_absolute() else (path.parent / p).resolve())
        row["structure"] = row["structure"] or "three-mass"
        key = (row["robot"], row["joint"], row["taken_at"])
        if key in seen:
            raise FleetError(
                f"{path}, line {line}: robot {row['robot']} joint {row['joint']} taken at "
                f"{row['taken_at']} is already on line {seen[key]}"
            )
        seen[key] = line
        rows.append(row)
    return rows


def _text(v: Any) -> str | None:
    if v is None:
        return None
    s = str(v).strip()
    return s or None


# --- one joint ----------------------------------------------------------------------


def process(job: dict, diagnose: bool = False) -> dict:
    """One joint of the night: the linear physical fit of ``job['structure']`` on its
    capture (scored on its validation capture when given) and, with ``diagnose``, the gap
    diagnosis against its previous model. Never raises: a failure is a row whose
    ``status`` is ``"error"`` and whose ``error`` says why."""
    import jointid

    t_wall = time.perf_counter()
    t_cpu = time.process_time()
    row: dict[str, Any] = {
        "robot": job["robot"],
        "joint": job["joint"],
        "taken_at": job["taken_at"],
        "capture": job["capture"],
        "structure": job["structure"],
        "status": "ok",
        "error": None,
        "fit_estimation": None,
        "fit_validation": None,
        "params": [],
        "warnings": [],
        "diagnosed": diagnose,
        "best": None,
        "best_parameters": [],
        "gap_closed": None,
        "fit_nominal_val": None,
        "fit_augmented_val": None,
        "verdict": None,
    }
    try:
        fit = jointid.fit(job["capture"], model=job["structure"], validation=job.get("validation"))
        doc = fit.to_dict()
        row["fit_estimation"] = doc.get("fit_estimation")
        row["fit_validation"] = doc.get("fit_validation")
        row["params"] = [
            {"name": k, "value": float(p.value), "std": float(p.std), "unit": p.unit}
            for k, p in sorted(fit.parameters.items())
        ]
        row["warnings"] = [f"fit: {w}" for w in doc.get("warnings", [])]
        if diagnose:
            if not job.get("validation"):
                raise FleetError("the diagnosis needs a validation capture (manifest column validation)")
            opts: dict[str, Any] = {"model": job["structure"], "quiet": True}
            if job.get("model_file"):
                opts["sim"] = job["model_file"]
            d = jointid.diagnose(job["capture"], validation=job["validation"], **opts).to_dict()
            row["best"] = d.get("best")
            row["gap_closed"] = d.get("gap_closed_share")
            row["fit_nominal_val"] = d.get("fit_nominal_val")
            row["fit_augmented_val"] = d.get("fit_augmented_val")
            row["verdict"] = d.get("verdict")
            row["best_parameters"] = _best_parameters(d)
            row["warnings"] += [f"diagnose: {w}" for w in d.get("warnings", [])]
    except Exception as e:  # one bad capture never stops the night
        row["status"] = "error"
        row["error"] = f"{type(e).__name__}: {e}"
    row["cpu_s"] = time.process_time() - t_cpu
    row["wall_s"] = time.perf_counter() - t_wall
    return row


def _best_parameters(d: dict) -> list[dict]:
    """The answer's effect parameters (the pair's when the answer is a pair)."""
    best = d.get("best")
    if not best or best == "none":
        return []
    cands = [d["pair"]] if d.get("pair") and d["pair"].get("name") == best else []
    cands += [c for c in d.get("effects", []) if c.get("name") == best]
    if not cands:
        return []
    return [
        {"name": k, "value": float(p["value"]), "std": float(p["std"]), "unit": p["unit"]}
        for k, p in sorted(cands[0].get("parameters", {}).items())
    ]


# --- the results dataset --------------------------------------------------------------


def _schema():
    import pyarrow as pa

    param = pa.struct(
        [("name", pa.string()), ("value", pa.float64()), ("std", pa.float64()), ("unit", pa.string())]
    )
    return pa.schema(
        [
            ("robot", pa.string()),
            ("joint", pa.string()),
            ("taken_at", pa.string()),
            ("capture", pa.string()),
            ("structure", pa.string()),
            ("status", pa.string()),
            ("error", pa.string()),
            ("fit_estimation", pa.float64()),
            ("fit_validation", pa.float64()),
            ("params", pa.list_(param)),
            ("warnings", pa.list_(pa.string())),
            ("diagnosed", pa.bool_()),
            ("best", pa.string()),
            ("best_parameters", pa.list_(param)),
            ("gap_closed", pa.float64()),
            ("fit_nominal_val", pa.float64()),
            ("fit_augmented_val", pa.float64()),
            ("verdict", pa.string()),
            ("cpu_s", pa.float64()),
            ("wall_s", pa.float64()),
            ("engine", pa.string()),
        ]
    )


#: columns that describe how a row was computed, not what: they differ between engines
#: and runs
TIMING = ("cpu_s", "wall_s", "engine")


def _prefix(shard: tuple[int, int] | None) -> str:
    """The part files' prefix of a run: ``part-`` alone, ``part-K-of-N-`` for shard K."""
    return "part-" if shard is None else f"part-{shard[0]}-of-{shard[1]}-"


def _write_part(partition: Path, prefix: str, index: int, rows: list[dict]) -> Path:
    """Rows as ``PREFIXINDEX.parquet``, written under a temporary name and renamed, so a
    part is either whole or absent."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.Table.from_pylist(rows, schema=_schema())
    final = partition / f"{prefix}{index:05d}.parquet"
    tmp = partition / f".{prefix}{index:05d}.parquet.tmp"
    pq.write_table(table, tmp)
    os.replace(tmp, final)
    return final


def _written(partition: Path, prefix: str) -> tuple[set, int]:
    """The joints (robot, joint, taken_at) already in a night's parts, and the next index
    of the parts named ``prefix``."""
    import pyarrow.parquet as pq

    keys: set = set()
    nxt = 0
    for p in sorted(partition.glob("part-*.parquet")):
        t = pq.read_table(p, columns=["robot", "joint", "taken_at"]).to_pylist()
        keys.update((r["robot"], r["joint"], r["taken_at"]) for r in t)
        rest = p.stem[len(prefix):]
        if p.stem.startswith(prefix) and rest.isdigit():
            nxt = max(nxt, int(rest) + 1)
    return keys, nxt


@dataclass
class RunSummary:
    """What a :func:`run` did, night by night."""

    out: str
    engine: str
    nights: dict = field(default_factory=dict)
    """night -> {"joints", "run", "resumed", "failed", "replaced"}"""
    cpu_s: float = 0.0
    """CPU seconds of the joints' work (the workers', summed)"""
    wall_s: float = 0.0

    def to_dict(self) -> dict:
        return {
            "schema": "jointid-fleet-run/1",
            "out": self.out,
            "engine": self.engine,
            "nights": self.nights,
            "cpu_s": self.cpu_s,
            "wall_s": self.wall_s,
        }


def run(
    manifest,
    out,
    diagnose: bool = False,
    engine: str = "local",
    ray_address: str | None = None,
    workers: int | None = None,
    progress=None,
    shard: tuple[int, int] | None = None,
) -> RunSummary:
    """Fits (and with ``diagnose`` diagnoses) every joint of ``manifest`` and writes one row
    per joint into ``out/date=NIGHT/`` (NIGHT the date of the row's ``taken_at``).

    A night whose earlier run finished (its ``_SUCCESS`` marker) is replaced whole; a night
    whose earlier run was killed is resumed: the joints already in its parts are not run
    again. Other nights' partitions are never touched. ``workers``: processes of the local
    engine, or CPUs of a Ray instance started for the run (default: this machine's cores).
    ``progress``: called with each finished row. ``shard=(K, N)``: only the manifest's rows
    ``K, K + N, K + 2N, ...`` (K from 0), their parts named ``part-K-of-N-*`` and their own
    marker, so N machines (a Kubernetes Indexed Job) share one night; replacing and
    resuming then touch this shard's parts only."""
    if engine not in ("local", "ray"):
        raise FleetError(f"engine {engine!r}: expected 'local' or 'ray'")
    if shard is not None and not (shard[1] >= 1 and 0 <= shard[0] < shard[1]):
        raise FleetError(f"shard {shard[0]} of {shard[1]}: expected 0 <= K < N")
    jobs = read_manifest(manifest)
    if shard is not None:
        jobs = jobs[shard[0] :: shard[1]]
    prefix = _prefix(shard)
    done_name = DONE if shard is None else f"{DONE}-{shard[0]}-of-{shard[1]}"
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    summary = RunSummary(out=str(out), engine=engine)
    t0 = time.perf_counter()
    todo: list[dict] = []
    nexts: dict[str, int] = {}
    by_night: dict[str, list[dict]] = {}
    for j in jobs:
        by_night.setdefault(j["night"], []).append(j)
    for night, js in sorted(by_night.items()):
        part = out / f"date={night}"
        replaced = False
        if (part / done_name).exists():
            if shard is None:
                shutil.rmtree(part)
            else:
                for p in list(part.glob(f"{prefix}*.parquet")) + [part / done_name]:
                    p.unlink()
            replaced = True
        part.mkdir(parents=True, exist_ok=True)
        for stale in part.glob(f".{prefix}*.tmp"):
            stale.unlink()
        done, nexts[night] = _written(part, prefix)
        left = [j for j in js if (j["robot"], j["joint"], j["taken_at"]) not in done]
        summary.nights[night] = {
            "joints": len(js),
            "run": len(left),
            "resumed": len(js) - len(left),
            "failed": 0,
            "replaced": replaced,
        }
        todo += left
    pending: dict[str, list[dict]] = {n: [] for n in by_night}
    left_per_night = {n: summary.nights[n]["run"] for n in by_night}
    for row in _execute(todo, diagnose, engine, ray_address, workers):
        night = _dt.datetime.fromisoformat(row["taken_at"]).date().isoformat()
        row["engine"] = engine
        summary.cpu_s += row["cpu_s"]
        if row["status"] != "ok":
            summary.nights[night]["failed"] += 1
        pending[night].append(row)
        left_per_night[night] -= 1
        if len(pending[night]) >= CHUNK or left_per_night[night] == 0:
            _write_part(out / f"date={night}", prefix, nexts[night], pending[night])
            nexts[night] += 1
            pending[night] = []
        if progress is not None:
            progress(row)
    for night in by_night:
        (out / f"date={night}" / done_name).write_text(
            json.dumps(summary.nights[night]) + "\n", encoding="utf-8"
        )
    summary.wall_s = time.perf_counter() - t0
    return summary


def _execute(jobs, diagnose, engine, ray_address, workers) -> Iterator[dict]:
    """The jobs' rows as they finish (any order)."""
    if not jobs:
        return
    n = workers or os.cpu_count() or 1
    if engine == "local":
        # one joint per task; the pool's processes import the library once each
        # the platform's start method (fork on Linux): the library holds no thread between
        # calls (its threads are scoped to one call), so a forked worker inherits none, and
        # a script that runs the fleet needs no `if __name__ == "__main__"` guard
        with ProcessPoolExecutor(max_workers=n) as pool:
            futures = [pool.submit(process, j, diagnose) for j in jobs]
            for f in as_completed(futures):
                yield f.result()
        return
    try:
        import ray
    except ImportError:
        raise FleetError("engine 'ray' needs the Python package ray (pip install 'jointid[ray]')") from None
    started = False
    if not ray.is_initialized():
        if ray_address:
            ray.init(address=ray_address, log_to_driver=False)
        else:
            ray.init(num_cpus=n, include_dashboard=False, log_to_driver=False)
        started = True
    try:
        task = ray.remote(num_cpus=1, max_retries=2)(process)
        refs = [task.remote(j, diagnose) for j in jobs]
        while refs:
            ready, refs = ray.wait(refs, num_returns=1)
            for r in ready:
                yield ray.get(r)
    finally:
        if started:
            ray.shutdown()


# --- drift --------------------------------------------------------------------------


def _rows(results, since: str | None) -> list[dict]:
    """Every ``ok`` row of the dataset with its parameters, through DuckDB."""
    import duckdb

    results = Path(results)
    parts = list(results.glob("date=*/part-*.parquet"))
    if not parts:
        raise FleetError(f"{results}: no results (expected date=YYYY-MM-DD/part-*.parquet)")
    con = duckdb.connect()
    where = "status = 'ok'"
    args: list[Any] = []
    if since:
        where += " AND CAST(date AS VARCHAR) >= ?"
        args.append(since)
    q = f"""
        SELECT CAST(date AS VARCHAR) AS night, robot, joint, taken_at, structure,
               fit_validation, fit_estimation, params, best, best_parameters, gap_closed
        FROM read_parquet('{results.as_posix()}/date=*/part-*.parquet', hive_partitioning = true)
        WHERE {where}
        ORDER BY robot, joint, taken_at
    """
    cur = con.execute(q, args)
    cols = [d[0] for d in cur.description]
    return [dict(zip(cols, r)) for r in cur.fetchall()]


def drift(results, since: str | None = None, z: float = 4.0, rel: float = 0.10) -> dict:
    """Per joint, against its first night in the results (from ``since`` on):

    - the parameters that moved beyond ``z`` times their combined standard deviation
      ``sqrt(σ₀² + σ²)`` *and* by more than ``rel`` of their first value, each with the
      first night it did so;
    - the effect the diagnosis named when it differs from the first night's (appeared,
      changed), or the same effect whose size grew beyond ``z`` combined σ;
    - the validation FIT night by night and its change.

    Returns ``{"schema", "z", "rel", "joints": [...]}``, the flagged joints first, ranked by
    their largest z-score."""
    rows = _rows(results, since)
    joints: dict[tuple, list[dict]] = {}
    for r in rows:
        joints.setdefault((r["robot"], r["joint"]), []).append(r)
    out = []
    for (robot, joint), rs in joints.items():
        rs.sort(key=lambda r: r["taken_at"])
        base = rs[0]
        base_p = {p["name"]: p for p in base["params"] or []}
        moved = []
        for name, p0 in sorted(base_p.items()):
            if not p0["value"]:
                # nought on the first night (a delay on its bound): no relative change to
                # read; the diagnosis's `time_delay` says when a delay appears
                continue
            series = []
            first = None
            first_change = math.nan
            for r in rs:
                p = next((q for q in r["params"] or [] if q["name"] == name), None)
                if p is None:
                    continue
                d = p["value"] - p0["value"]
                sd = math.hypot(p0["std"] or 0.0, p["std"] or 0.0)
                zz = abs(d) / sd if sd > 0 else (math.inf if d else 0.0)
                rr = abs(d) / abs(p0["value"])
                series.append(
                    {"night": r["night"], "value": p["value"], "std": p["std"], "z": zz, "rel": rr}
                )
                if first is None and zz > z and rr > rel:
                    first = r["night"]
                    first_change = d / p0["value"]
            if first is not None:
                last = series[-1]
                moved.append(
                    {
                        "name": name,
                        "unit": p0["unit"],
                        "first_night": first,
                        "first_change": first_change,
                        "from": p0["value"],
                        "to": last["value"],
                        "change": last["value"] / p0["value"] - 1.0,
                        "z": max(s["z"] for s in series),
                        "series": series,
                    }
                )
        effects = _effect_changes(rs, z)
        fits = [{"night": r["night"], "fit_validation": r["fit_validation"]} for r in rs]
        vals = [f["fit_validation"] for f in fits if f["fit_validation"] is not None]
        out.append(
            {
                "robot": robot,
                "joint": joint,
                "nights": [r["night"] for r in rs],
                "flagged": bool(moved or effects),
                "moved": moved,
                "effects": effects,
                "fit_validation": fits,
                "fit_change": (vals[-1] - vals[0]) if len(vals) > 1 else None,
                "score": max([m["z"] for m in moved] + [e.get("z", z) for e in effects] + [0.0]),
            }
        )
    out.sort(key=lambda j: (not j["flagged"], -min(j["score"], 1e300), j["robot"], j["joint"]))
    return {"schema": "jointid-fleet-drift/1", "z": z, "rel": rel, "since": since, "joints": out}


def _effect_changes(rs: list[dict], z: float) -> list[dict]:
    """The nights the diagnosis's answer differs from the first night's, or grew."""
    diagnosed = [r for r in rs if r["best"] is not None]
    if len(diagnosed) < 2:
        return []
    base = diagnosed[0]
    out = []
    for r in diagnosed[1:]:
        if r["best"] != base["best"]:
            kind = "appeared" if base["best"] == "none" else ("vanished" if r["best"] == "none" else "changed")
            out.append({"night": r["night"], "kind": kind, "from": base["best"], "to": r["best"]})
            break
        b0 = {p["name"]: p for p in base["best_parameters"] or []}
        for p in r["best_parameters"] or []:
            q = b0.get(p["name"])
            if q is None:
                continue
            sd = math.hypot(q["std"] or 0.0, p["std"] or 0.0)
            zz = abs(p["value"] - q["value"]) / sd if sd > 0 else 0.0
            if zz > z and abs(p["value"]) > abs(q["value"]):
                out.append(
                    {"night": r["night"], "kind": "grew", "from": base["best"], "to": r["best"],
                     "parameter": p["name"], "z": zz, "from_value": q["value"], "to_value": p["value"]}
                )
                return out
    return out


def drift_table(report: dict, all_joints: bool = False) -> str:
    """The drift report as a ranked table for a terminal."""
    lines = [f"{'robot':<10} {'joint':<8} {'first night':<12} what"]
    for j in report["joints"]:
        if not j["flagged"] and not all_joints:
            continue
        whats = [_moved_words(m) for m in j["moved"]] + [
            f"effect {e['kind']}: {e['from']} -> {e['to']}" for e in j["effects"]
        ]
        first = min([m["first_night"] for m in j["moved"]] + [e["night"] for e in j["effects"]] or ["-"])
        fit = f"; validation FIT {j['fit_change']:+.2f} points" if j["fit_change"] is not None else ""
        lines.append(f"{j['robot']:<10} {j['joint']:<8} {first:<12} {', '.join(whats) or 'unchanged'}{fit}")
    n = sum(j["flagged"] for j in report["joints"])
    lines.append(
        f"{n} of {len(report['joints'])} joints flagged (moved beyond {report['z']} combined σ "
        f"and {100 * report['rel']:.0f} % of the first night's value)"
    )
    return "\n".join(lines)


def _moved_words(m: dict) -> str:
    """One moved parameter in words: its change on the first night it was flagged and on
    the last night read."""
    return (
        f"{m['name']} {100 * m['first_change']:+.1f} % on {m['first_night']} (now "
        f"{100 * m['change']:+.1f} %, z up to {m['z']:.1f})"
    )


def _trend_svg(m: dict, width: int = 260, height: int = 90) -> str:
    """One parameter's values night by night with ±σ bars, its first value dashed."""
    s = m["series"]
    lo = min(p["value"] - p["std"] for p in s)
    hi = max(p["value"] + p["std"] for p in s)
    if hi <= lo:
        hi, lo = lo + 1.0, lo - 1.0
    pad = 0.08 * (hi - lo)
    lo, hi = lo - pad, hi + pad
    x = lambda i: 30 + (width - 55) * (i / max(len(s) - 1, 1))
    y = lambda v: 18 + (height - 38) * (1 - (v - lo) / (hi - lo))
    pts = " ".join(f"{x(i):.1f},{y(p['value']):.1f}" for i, p in enumerate(s))
    bars = "".join(
        f'<line x1="{x(i):.1f}" x2="{x(i):.1f}" y1="{y(p["value"] - p["std"]):.1f}" '
        f'y2="{y(p["value"] + p["std"]):.1f}" stroke="#555"/>'
        for i, p in enumerate(s)
    )
    dots = "".join(
        f'<circle cx="{x(i):.1f}" cy="{y(p["value"]):.1f}" r="3" '
        f'fill="{"#c0392b" if p["night"] >= m["first_night"] else "#2c3e50"}"/>'
        for i, p in enumerate(s)
    )
    labels = "".join(
        f'<text x="{x(i):.1f}" y="{height - 4}" font-size="8" text-anchor="middle">{p["night"][5:]}</text>'
        for i, p in enumerate(s)
    )
    base = y(s[0]["value"])
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        f'role="img" aria-label="{html.escape(m["name"])} night by night">'
        f'<line x1="30" x2="{width - 10}" y1="{base:.1f}" y2="{base:.1f}" stroke="#999" '
        f'stroke-dasharray="4 3"/>'
        f'<polyline points="{pts}" fill="none" stroke="#2c3e50"/>{bars}{dots}{labels}'
        f'<text x="2" y="10" font-size="9">{html.escape(m["name"])} [{html.escape(m["unit"])}]</text>'
        "</svg>"
    )


def drift_html(report: dict) -> str:
    """The drift report as one self-contained HTML page: the ranked table, and a small
    trend plot per moved parameter of each flagged joint."""
    rows = []
    for j in report["joints"]:
        if not j["flagged"]:
            continue
        what = "; ".join(
            [html.escape(_moved_words(m)) for m in j["moved"]]
            + [f"effect {e['kind']}: {html.escape(str(e['from']))} → {html.escape(str(e['to']))} on {e['night']}" for e in j["effects"]]
        )
        plots = "".join(_trend_svg(m) for m in j["moved"])
        fit = "" if j["fit_change"] is None else f"{j['fit_change']:+.2f}"
        rows.append(
            f'<tr class="flagged" data-robot="{html.escape(j["robot"])}" data-joint="{html.escape(j["joint"])}">'
            f"<td>{html.escape(j['robot'])}</td><td>{html.escape(j['joint'])}</td><td>{what}</td>"
            f"<td>{fit}</td><td>{plots}</td></tr>"
        )
    n = len(rows)
    total = len(report["joints"])
    return (
        "<!doctype html><html lang=\"en\"><head><meta charset=\"utf-8\">"
        "<title>jointid fleet drift</title><style>body{font-family:sans-serif;margin:1.5em}"
        "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:4px 8px;"
        "vertical-align:top}th{background:#eee}</style></head><body>"
        f"<h1>Fleet drift</h1><p id=\"summary\">{n} of {total} joints flagged: a parameter moved "
        f"beyond {report['z']} combined σ and {100 * report['rel']:.0f} % of its first night's "
        "value, or the diagnosis's effect appeared, changed or grew.</p>"
        "<table id=\"drift\"><thead><tr><th>robot</th><th>joint</th><th>what moved</th>"
        "<th>validation FIT change [points]</th><th>trend (dashed: first night; red: flagged)</th></tr></thead>"
        f"<tbody>{''.join(rows)}</tbody></table></body></html>\n"
    )


# --- a fleet to test on ----------------------------------------------------------------

#: the planted drift kinds, with what changes per night after the first
DRIFT_KINDS = {
    "friction": "motor viscous friction f_m grows by 60 % of its first value per night",
    "stiffness": "gearbox stiffness k_g drops by 15 % of its first value per night",
    "backlash": "a backlash opens from the second night on, widening each night",
    "mode": "a parallel mode appears from the second night on",
}

#: reference RMS [rad] of the joints whose controller has feedforward (below the torque
#: limit; the others take the simulator's default, 0.02)
FEEDFORWARD_RMS = 0.006

_BASE = {
    "J_m": 1e-3,
    "J_a1": 11.0,
    "J_a2": 0.6,
    "k_g": 1.3e5,
    "k_a": 7000.0,
    "d_g": 80.0,
    "d_a": 4.0,
    "f_m": 2e-3,
}


def simulate_fleet(robots: int, joints_per_robot: int, nights: int, out, seed: int = 1,
                   drifting: float = 0.5, periods: int = 4, first_night: str = "2026-12-01",
                   kinds: list[str] | None = None) -> dict:
    """Writes ``nights`` nights of captures (estimation and validation, ``.jcap``) of
    ``robots × joints_per_robot`` simulated three-mass joints (each parameter ±30 % of a
    nominal joint, the simulator's default sensors; every other joint's controller with
    velocity and torque feedforward, excited at 0.006 rad RMS, since at the default 0.02 its
    feedforward drives the 12 N·m torque limit on 2,225 of 24,000 samples) and
    one manifest per night, ``out/manifest-NIGHT.csv``, plus ``out/manifest.csv`` with every
    night. About ``drifting`` of the joints drift, cycling through ``kinds`` (default: every
    kind of :data:`DRIFT_KINDS`); the truth (each joint's parameters night by night, its
    drift and the first night it shows) goes to ``out/truth.json``."""
    import numpy as np

    import jointid

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    day0 = _dt.date.fromisoformat(first_night)
    kinds = list(kinds or DRIFT_KINDS)
    unknown = [k for k in kinds if k not in DRIFT_KINDS]
    if unknown:
        raise FleetError(f"drift kind(s) {', '.join(unknown)}: expected {', '.join(DRIFT_KINDS)}")
    truth = {"schema": "jointid-fleet-truth/1", "kinds": DRIFT_KINDS, "joints": []}
    manifest_all = []
    n = 0
    for ri in range(robots):
        for ji in range(joints_per_robot):
            base = {k: v * float(rng.uniform(0.7, 1.3)) for k, v in _BASE.items()}
            drifts = (n % round(1 / drifting) == 0) if drifting > 0 else False
            kind = kinds[(n // max(round(1 / drifting), 1)) % len(kinds)] if drifts else "none"
            robot, joint = f"r{ri + 1:03d}", f"j{ji + 1}"
            jt = {"robot": robot, "joint": joint, "drift": kind, "nights": []}
            for night in range(nights):
                p = dict(base)
                effects: list[str] = []
                if kind == "friction":
                    p["f_m"] = base["f_m"] * (1 + 0.6 * night)
                elif kind == "stiffness":
                    p["k_g"] = base["k_g"] * (1 - 0.15 * night)
                elif kind == "backlash" and night >= 1:
                    effects = [f"backlash:width={2e-5 * night:g}"]
                elif kind == "mode" and night >= 1:
                    effects = ["extra_mode"]
                date = (day0 + _dt.timedelta(days=night)).isoformat()
                d = out / "captures" / date
                d.mkdir(parents=True, exist_ok=True)
                files = {}
                for which, s in (("est", 1), ("val", 2)):
                    path = d / f"{robot}-{joint}-{which}.jcap"
                    jointid.simulate(
                        path,
                        model="three-mass",
                        param=[f"{k}={v!r}" for k, v in p.items()],
                        effect=effects or None,
                        periods=periods,
                        seed=1000 * n + 10 * night + s,
                        feedforward=(n % 2 == 1),
                        rms=FEEDFORWARD_RMS if n % 2 == 1 else None,
                        force=True,
                    )
                    files[which] = path.relative_to(out).as_posix()
                jt["controller"] = "cascade with feedforward" if n % 2 == 1 else "cascade"
                row = {
                    "robot": robot,
                    "joint": joint,
                    "taken_at": f"{date}T02:00:00",
                    "capture": files["est"],
                    "validation": files["val"],
                    "structure": "three-mass",
                }
                manifest_all.append(row)
                jt["nights"].append({"night": date, "params": p, "effects": effects})
            jt["shows_from"] = (day0 + _dt.timedelta(days=1)).isoformat() if kind != "none" and nights > 1 else None
            truth["joints"].append(jt)
            n += 1
    cols = ["robot", "joint", "taken_at", "capture", "validation", "structure"]
    for night in sorted({r["taken_at"][:10] for r in manifest_all}):
        _write_csv(out / f"manifest-{night}.csv", cols, [r for r in manifest_all if r["taken_at"].startswith(night)])
    _write_csv(out / "manifest.csv", cols, manifest_all)
    (out / "truth.json").write_text(json.dumps(truth, indent=1) + "\n", encoding="utf-8")
    return truth


def _write_csv(path: Path, cols: list[str], rows: list[dict]) -> None:
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        w.writerows(rows)


# --- the command line -------------------------------------------------------------------


def main(argv: Iterable[str] | None = None) -> int:
    """``python -m jointid.fleet run|drift|simulate ...`` (``--help`` for each)."""
    ap = argparse.ArgumentParser(prog="jointid-fleet", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run", help="fit (and diagnose) every joint of a manifest into a Parquet dataset")
    r.add_argument("manifest")
    r.add_argument("--out", required=True, help="results directory (Hive-partitioned by date)")
    r.add_argument("--diagnose", action="store_true", help="also diagnose each joint's gap")
    r.add_argument("--engine", choices=["local", "ray"], default="local")
    r.add_argument("--ray-address", default=None, help="an existing Ray cluster (default: a local instance)")
    r.add_argument("--workers", type=int, default=None, help="processes or Ray CPUs (default: the cores)")
    r.add_argument("--shard", default=None, metavar="K/N",
                   help="only rows K, K+N, ... of the manifest (K from 0): one of N machines")
    r.add_argument("--json", action="store_true")
    d = sub.add_parser("drift", help="parameters and effects that moved, per joint")
    d.add_argument("results")
    d.add_argument("--since", default=None, help="first night to read (YYYY-MM-DD)")
    d.add_argument("--z", type=float, default=4.0, help="z-score threshold (combined σ)")
    d.add_argument("--rel", type=float, default=0.10, help="relative change threshold")
    d.add_argument("--json", action="store_true")
    d.add_argument("--html", default=None, help="write the HTML page here")
    d.add_argument("--all", action="store_true", help="list unflagged joints too")
    s = sub.add_parser("simulate", help="a simulated fleet with planted drift and its truth")
    s.add_argument("--robots", type=int, required=True)
    s.add_argument("--joints-per-robot", type=int, required=True)
    s.add_argument("--nights", type=int, required=True)
    s.add_argument("--out", required=True)
    s.add_argument("--seed", type=int, default=1)
    s.add_argument("--periods", type=int, default=4)
    a = ap.parse_args(list(argv) if argv is not None else None)
    try:
        if a.cmd == "run":
            def say(row):
                if not a.json:
                    tag = "ok" if row["status"] == "ok" else f"FAILED: {row['error']}"
                    print(f"{row['taken_at'][:10]} {row['robot']} {row['joint']}: {tag}", file=sys.stderr)

            shard = None
            if a.shard:
                try:
                    k, n = (int(x) for x in a.shard.split("/"))
                except ValueError:
                    raise FleetError(f"--shard {a.shard!r}: expected K/N, e.g. 0/4") from None
                shard = (k, n)
            summ = run(a.manifest, a.out, diagnose=a.diagnose, engine=a.engine,
                       ray_address=a.ray_address, workers=a.workers, progress=say, shard=shard)
            if a.json:
                print(json.dumps(summ.to_dict(), indent=1))
            else:
                for night, nn in summ.nights.items():
                    print(f"{night}: {nn['joints']} joints, {nn['run']} run, {nn['resumed']} already "
                          f"written, {nn['failed']} failed{' (partition replaced)' if nn['replaced'] else ''}")
                print(f"{summ.cpu_s:.1f} s CPU in the joints, {summ.wall_s:.1f} s wall; results in {summ.out}")
            return 1 if any(nn["failed"] for nn in summ.nights.values()) else 0
        if a.cmd == "drift":
            rep = drift(a.results, since=a.since, z=a.z, rel=a.rel)
            if a.html:
                Path(a.html).write_text(drift_html(rep), encoding="utf-8")
            print(json.dumps(rep, indent=1) if a.json else drift_table(rep, a.all))
            return 0
        t = simulate_fleet(a.robots, a.joints_per_robot, a.nights, a.out, seed=a.seed, periods=a.periods)
        print(f"{len(t['joints'])} joints × {a.nights} nights in {a.out} (manifest.csv, truth.json)")
        return 0
    except FleetError as e:
        print(f"jointid-fleet: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
