#!/usr/bin/env bash
# Builds the Python package (crates/radiosity-py: pyo3 + maturin) in a fresh virtual
# environment with only pip, and runs its pytest suite (closed forms, the Cornell box's
# occluded view factors against the committed reference, the furnace, bad input, the GIL
# released, Ctrl-C). Skips with a message when Python, venv or PyPI cannot be had; a build
# or test failure fails. The library built for the tests is reused (CARGO_TARGET_DIR).
#   checks/python/run.sh
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
py=$(command -v python3 || true)
if [ -z "$py" ]; then
  echo "python check: SKIPPED (python3 not found)"
  exit 0
fi
env=$(mktemp -d)
trap 'rm -rf "$env"' EXIT
if ! "$py" -m venv "$env" >/dev/null 2>&1; then
  echo "python check: SKIPPED (python3 -m venv failed: install python3-venv)"
  exit 0
fi
if ! "$env/bin/pip" install -q "numpy>=1.21" pytest; then
  echo "python check: SKIPPED (pip could not install numpy, pytest: no PyPI?)"
  exit 0
fi
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$root/target}"
# The README's command (pip fetches maturin into its build environment).
if ! "$env/bin/pip" install -q "$root/crates/radiosity-py"; then
  echo "python check: FAILED (the package did not build)"
  exit 1
fi
"$env/bin/python" -m pytest -q "$root/crates/radiosity-py/tests"
status=$?
if [ $status -eq 0 ]; then echo "python check: pytest passed"; else echo "python check: pytest FAILED"; fi
exit $status
