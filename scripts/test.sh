#!/usr/bin/env bash
# Install everything the test suite needs (Debian's chromium for the browser tests, the package
# with its test extras) and run lint, the type checker and the whole suite. Extra arguments go
# to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! command -v chromium >/dev/null 2>&1; then
  echo "== installing Debian's chromium (browser tests)"
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >/dev/null
fi

echo "== installing routefuse with its test extras"
python3 -m pip install -q --disable-pip-version-check -e '.[test]'

echo "== ruff"
python3 -m ruff check estimator inspector tests benchmarks scripts

echo "== mypy (strict on estimator/)"
python3 -m mypy

echo "== pytest"
python3 -m pytest -q "$@"
