#!/usr/bin/env bash
# Run bench/peers.py (edtmap vs scipy vs edt) in bench/.venv, creating it if needed.
# All arguments are passed through, e.g.: bash bench/peers.sh --quick
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="$here/.venv"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
if ! "$venv/bin/python" -c 'import numpy, scipy, edt' 2>/dev/null; then
    "$venv/bin/pip" install -q numpy scipy edt
fi
cd "$here/.."
exec "$venv/bin/python" "$here/peers.py" "$@"
