#!/usr/bin/env bash
# The Python package's tests (part of the README's test command): builds the abi3 wheel
# with maturin, installs it into a fresh virtual environment under the target directory,
# runs pytest (python/tests: the package against the simulated truth and against the
# release `jointid` binary's --json output; the fleet on the local engine and on a local Ray
# instance) and python/examples/quickstart.py.
# Needs python3 (≥ 3.9) with venv and pip, and PyPI for maturin, pytest, numpy, pandas, and
# the fleet's pyarrow, duckdb and ray.
set -euo pipefail
cd "$(dirname "$0")"
root="$(cd .. && pwd)"
target="${CARGO_TARGET_DIR:-$root/target}"
export CARGO_TARGET_DIR="$target"
python="${PYTHON:-python3}"
work="$target/python-ci"

if ! "$python" -c 'import sys, venv; assert sys.version_info >= (3, 9)' 2>/dev/null; then
    echo "python/ci.sh: needs $python 3.9 or later with the venv module (set PYTHON=...)" >&2
    exit 2
fi

echo "== python: fresh virtual environment $work/venv"
rm -rf "$work"
mkdir -p "$work"
"$python" -m venv "$work/venv"
"$work/venv/bin/pip" install --quiet --upgrade pip
"$work/venv/bin/pip" install --quiet maturin pytest numpy pandas pyarrow duckdb ray

echo "== python: abi3 wheel (maturin build --release)"
start=$(date +%s)
# `jointid/test-support`: the library's features as `cargo test --release` resolved them
# (the command line's tests turn the fixtures on), so the wheel links the library that build
# compiled instead of compiling it again; the bindings never call the fixtures
"$work/venv/bin/maturin" build --release --features jointid/test-support --out "$work/wheels"
echo "wheel built in $(( $(date +%s) - start )) s"
"$work/venv/bin/pip" install --quiet "$work"/wheels/jointid-*.whl

# the release binary the tests compare with: the one `cargo test --release` built beside
# the tests (.ci/run gives it), else built here
if [ -z "${JOINTID_BIN:-}" ]; then
    echo "== python: the release binary the tests compare with"
    cargo build --release --manifest-path "$root/Cargo.toml" -p jointid-cli
    export JOINTID_BIN="$target/release/jointid"
fi
echo "== python: comparing with $JOINTID_BIN"

echo "== python: pytest"
# run from the tests directory, so `import jointid` is the installed wheel, not python/jointid
(cd tests && "$work/venv/bin/pytest" -q -p no:cacheprovider .)

echo "== python: examples/quickstart.py"
"$work/venv/bin/python" examples/quickstart.py "$work/quickstart"
