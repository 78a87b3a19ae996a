#!/usr/bin/env bash
# bench/python.py in bench/.venv-python: installs the edtmap package from
# ./python (a release build) with numpy, scipy and edt, then runs it.
# Arguments pass through, e.g.: bash bench/python.sh --sizes 128 --repeat 3
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="$here/.venv-python"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
"$venv/bin/pip" install -q numpy scipy edt
"$venv/bin/pip" install -q "$here/../python"
cd "$here/.."
exec "$venv/bin/python" "$here/python.py" "$@"
