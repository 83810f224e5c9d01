#!/usr/bin/env bash
# A Python virtual environment for the ignored EGM tests that check forcecell against code it did not
# write (docs/egm.md): created under target/egm-venv if missing, with the packages given installed from
# PyPI by pip. Prints the environment's python on its last line.
#
# Usage: scripts/egm-venv.sh PACKAGE...   (e.g. protobuf grpcio-tools abb-robot-client)
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
venv="${CARGO_TARGET_DIR:-$here/target}/egm-venv"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv" >&2
fi
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check "$@" >&2
echo "$venv/bin/python"
