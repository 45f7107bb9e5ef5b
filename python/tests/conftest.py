"""Shared captures: two short runs of the simulated three-mass joint (4 periods, 12 s at
2 kHz), written once per session by ``jointid.simulate``."""

import os
import shutil

import pytest

import jointid


@pytest.fixture(scope="session")
def captures(tmp_path_factory):
    d = tmp_path_factory.mktemp("captures")
    est = jointid.simulate(d / "est.jcap", model="three-mass", periods=4, seed=1)
    val = jointid.simulate(d / "val.jcap", model="three-mass", periods=4, seed=2)
    return {"dir": d, "est": est, "val": val}


@pytest.fixture(scope="session")
def cli():
    """The `jointid` binary the package is compared with: $JOINTID_BIN (python/ci.sh sets
    it to the release build), else `jointid` on PATH."""
    path = os.environ.get("JOINTID_BIN") or shutil.which("jointid")
    if not path:
        pytest.fail("set JOINTID_BIN to the jointid binary (python/ci.sh does)")
    return path
