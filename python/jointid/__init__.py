"""jointid: identification of one robot joint from closed-loop data.

Every function runs the ``jointid`` command line's own code in this process (the Rust
library through the native module ``jointid._native``): ``fit``, ``simulate``,
``analyze`` and ``diagnose`` take the command's options as keyword arguments
(``current_loop_tau=4e-4`` is ``--current-loop-tau 4e-4``, ``True`` a bare flag, a list a
repeated flag) and return a result whose ``to_dict()`` is the command's ``--json``
document. Errors raise :class:`JointidError` with the message the command line prints.
"""

from __future__ import annotations

import copy
import json
import os
import tempfile
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from . import _native
from ._native import JointidError

__all__ = [
    "JointidError",
    "Parameter",
    "Result",
    "FitResult",
    "AnalyzeResult",
    "SimulateResult",
    "read_capture",
    "write_capture",
    "fit",
    "simulate",
    "analyze",
    "diagnose",
    "run",
]


class Parameter(NamedTuple):
    """One fitted parameter: value and standard deviation in ``unit``."""

    value: float
    std: float
    unit: str


def _flags(options: dict[str, Any]) -> list[str]:
    """Keyword arguments as command-line flags: ``a_b=v`` -> ``--a-b v``; ``True`` a bare
    flag, ``False``/``None`` nothing, a list or tuple the flag once per item."""
    out: list[str] = []
    for key, value in options.items():
        flag = "--" + key.replace("_", "-")
        if value is None or value is False:
            continue
        if value is True:
            out.append(flag)
        elif isinstance(value, (list, tuple)):
            for v in value:
                out += [flag, _arg(v)]
        else:
            out += [flag, _arg(value)]
    return out


def _arg(value: Any) -> str:
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if isinstance(value, float):
        return repr(value)
    return str(value)


def run(*args: str) -> tuple[dict, int, dict | None]:
    """Runs ``jointid --json ARGS...``: its JSON document, its exit code (0, or 1 when a
    check asked for failed, as ``--strict``) and, for a linear fit, the fitted model's
    matrices. Raises :class:`JointidError` with the command line's message."""
    text, code, ss = _native.run([_arg(a) for a in args])
    return json.loads(text), code, ss


class Result:
    """A command's ``--json`` document. ``to_dict()`` returns it (a copy); its fields are
    readable as attributes and items. ``check_failed``: the command would exit 1 (a check
    asked for failed, e.g. ``strict=True`` and a warning)."""

    def __init__(self, doc: dict, code: int = 0):
        self._doc = doc
        self.check_failed = code == 1

    def to_dict(self) -> dict:
        """The ``--json`` document of the command, as ``json.loads`` reads it."""
        return copy.deepcopy(self._doc)

    def __getitem__(self, key: str) -> Any:
        return self._doc[key]

    def __getattr__(self, name: str) -> Any:
        doc = self.__dict__.get("_doc", {})
        if name in doc:
            return doc[name]
        raise AttributeError(name)

    def __repr__(self) -> str:
        return f"<jointid {self._doc.get('schema', 'result')}>"


def _array(values: Any) -> np.ndarray:
    return np.asarray([np.nan if v is None else v for v in values], dtype=float)


class FitResult(Result):
    """``fit``'s result: ``parameters`` (name -> :class:`Parameter`), ``fit_estimation``,
    ``fit_validation`` [%], ``resonances_hz``, ``antiresonances_hz`` (numpy arrays),
    ``warnings``, and the fitted model's matrices by :meth:`state_space`."""

    def __init__(self, doc: dict, code: int, ss: dict | None):
        super().__init__(doc, code)
        self._ss = ss

    @property
    def parameters(self) -> dict[str, Parameter]:
        """Parameters by name, each value, standard deviation and unit (empty for a black
        box; the nonlinear fit's structure, ``tau_c`` and ``offset``)."""
        return {k: Parameter(p["value"], p["std"], p["unit"]) for k, p in self._doc["parameters"].items()}

    @property
    def resonances_hz(self) -> np.ndarray:
        return _array(self._doc.get("resonances_hz", []))

    @property
    def antiresonances_hz(self) -> np.ndarray:
        return _array(self._doc.get("antiresonances_hz", []))

    def state_space(self, continuous: bool = False):
        """``(A, B, C, D)`` as numpy arrays (``B`` n×1, ``C`` 1×n, ``D`` 1×1): the discrete
        model at ``ts`` (``self.ts_model``), or with ``continuous=True`` the physical model's
        continuous form ``ẋ = F x + G u, y = H x + D u`` (seed 000 eq. (10))."""
        if self._ss is None:
            raise JointidError(
                f"{self._doc.get('model')}: a model with effects has no state-space form; "
                "it is simulated with the exact laws"
            )
        if continuous:
            c = self._ss["continuous"]
            if c is None:
                raise JointidError(f"{self._ss['model']}: a black box has no continuous model")
            a, b, cc, d = c["f"], c["g"], c["h"], c["d"]
        else:
            a, b, cc, d = self._ss["a"], self._ss["b"], self._ss["c"], self._ss["d"]
        n = len(b)
        return (
            np.asarray(a, dtype=float).reshape(n, n),
            np.asarray(b, dtype=float).reshape(n, 1),
            np.asarray(cc, dtype=float).reshape(1, n),
            np.asarray([[d]], dtype=float),
        )

    @property
    def ts_model(self) -> float | None:
        """Sample interval of the discrete model [s] (None without a state-space form)."""
        return None if self._ss is None else self._ss["ts"]


class AnalyzeResult(Result):
    """``analyze``'s result; ``freq_hz``, ``frf`` (complex) and ``frf_sigma`` are the FRF
    at the excited lines as numpy arrays."""

    def _frf(self) -> dict:
        return self._doc["analysis"]["frf"]

    @property
    def freq_hz(self) -> np.ndarray:
        return _array(self._frf()["freq_hz"])

    @property
    def frf(self) -> np.ndarray:
        g = self._frf()["g"]
        return np.asarray([complex(v["re"], v["im"]) for v in g], dtype=complex)

    @property
    def frf_sigma(self) -> np.ndarray:
        return _array(self._frf()["sigma"])


class SimulateResult(Result):
    """``simulate``'s result; ``path`` the file written, ``data`` it read back
    (:func:`read_capture`)."""

    @property
    def path(self) -> str:
        return self._doc["out"]

    @property
    def data(self) -> pd.DataFrame:
        return read_capture(self.path)


def read_capture(path, time=None, input=None, output=None, reference=None) -> pd.DataFrame:
    """The file as the analysis commands read it (a ``.jcap`` capture, a capture CSV, or
    a CSV whose columns ``time``, ``input``, ``output`` name): one row per sample of
    every gap-free segment in time order, columns ``t`` [s], ``theta_ref`` [rad] (when
    recorded), ``u`` [N·m], ``theta_m`` [rad] and ``segment`` (from 1). ``df.attrs``
    holds ``file``, ``ts`` [s], ``excitation`` (the board's excitation config, or None),
    ``meta`` (other ``# key=value`` comments), ``segments`` (as ``jointid info`` lists
    them), ``gaps`` (``after_segment``, ``start_s``, ``end_s``, missing ``samples``) and
    the reader's ``notes``."""
    cols, attrs = _native.read_capture(os.fspath(path), time, input, output, reference)
    frame = {k: np.frombuffer(v, dtype="<f8").copy() for k, v in cols.items()}
    frame["segment"] = frame["segment"].astype(np.int64)
    order = [c for c in ("t", "theta_ref", "u", "theta_m", "segment") if c in frame]
    df = pd.DataFrame({c: frame[c] for c in order})
    df.attrs.update(json.loads(attrs))
    return df


class _DataFile:
    """A path for the command line: ``data`` itself when it is a path, or a capture CSV
    written from a DataFrame (``read_capture``'s columns and attrs) into a temporary
    directory removed on exit."""

    def __init__(self, data):
        self._dir = None
        if isinstance(data, pd.DataFrame):
            self._dir = tempfile.TemporaryDirectory(prefix="jointid-")
            self.path = os.path.join(self._dir.name, "data.csv")
            write_capture(data, self.path)
        else:
            self.path = os.fspath(data)

    def __enter__(self):
        return self.path

    def __exit__(self, *exc):
        if self._dir is not None:
            self._dir.cleanup()


def write_capture(df: pd.DataFrame, path) -> None:
    """Writes ``df`` (:func:`read_capture`'s columns ``t``, ``theta_ref``, ``u``,
    ``theta_m``; ``attrs`` ``excitation``, ``ts``, ``meta``) as a capture CSV, by the
    library's writer (as ``jointid export``); ``t`` as given, so a jump by whole sample
    intervals reads back as a gap. Replaces ``path`` when it exists."""
    missing = [c for c in ("t", "theta_ref", "u", "theta_m") if c not in df.columns]
    if missing:
        raise JointidError(
            f"the DataFrame lacks column(s) {', '.join(missing)}: a capture has t, theta_ref, u, "
            "theta_m (read_capture's columns)"
        )
    t = df["t"].to_numpy(dtype=float)
    ts = df.attrs.get("ts") or (float(np.median(np.diff(t))) if len(t) > 1 else 0.0)
    excitation = df.attrs.get("excitation")
    meta = {str(k): str(v) for k, v in (df.attrs.get("meta") or {}).items()}
    _native.write_capture_csv(
        os.fspath(path),
        t.tolist(),
        df["theta_ref"].to_numpy(dtype=float).tolist(),
        df["u"].to_numpy(dtype=float).tolist(),
        df["theta_m"].to_numpy(dtype=float).tolist(),
        None if excitation is None else json.dumps(excitation),
        float(ts),
        meta,
    )


def fit(data, model: str = "three-mass", validation=None, **options) -> FitResult:
    """``jointid fit DATA --model MODEL [--validation VAL] ...``: ``data`` and
    ``validation`` a path or a DataFrame from :func:`read_capture`; ``options`` the
    command's other flags (``effect=[...]``, ``domain="time"``, ``save="m.json"``, ...)."""
    with _DataFile(data) as d, _DataFile(validation) if validation is not None else _Nothing() as v:
        doc, code, ss = run("fit", d, "--model", model, *(["--validation", v] if v else []), *_flags(options))
    return FitResult(doc, code, ss)


class _Nothing:
    def __enter__(self):
        return None

    def __exit__(self, *exc):
        return None


def simulate(out, **options) -> SimulateResult:
    """``jointid simulate --out OUT ...``: writes the capture ``out`` (``.jcap``, or a
    capture CSV for ``.csv``); ``options`` as the command's flags (``model="two-mass"``,
    ``effect=["backlash"]``, ``periods=4``, ``seed=1``, ``force=True``, ...)."""
    doc, code, _ = run("simulate", "--out", out, *_flags(options))
    return SimulateResult(doc, code)


def analyze(data, **options) -> AnalyzeResult:
    """``jointid analyze DATA ...``: FRF, noise and odd/even distortion."""
    with _DataFile(data) as d:
        doc, code, _ = run("analyze", d, *_flags(options))
    return AnalyzeResult(doc, code)


def diagnose(data, validation=None, **options) -> Result:
    """``jointid diagnose DATA --validation VAL ...``: which unmodelled effect makes the
    model depart from the measured joint (``model="three-mass"``, ``effects="all"``...)."""
    with _DataFile(data) as d, _DataFile(validation) if validation is not None else _Nothing() as v:
        doc, code, _ = run("diagnose", d, *(["--validation", v] if v else []), *_flags(options))
    return Result(doc, code)
