"""The planner example on the map `edtmap demo` saves."""

import subprocess
import sys
from pathlib import Path

from test_mapper import cli

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "plan_path.py"


def test_plan_path_on_the_demo_map(tmp_path):
    cli("demo", "--frames", 40, "--out", tmp_path / "demo", cwd=tmp_path)
    done = subprocess.run([sys.executable, str(EXAMPLE), str(tmp_path / "demo" / "map.edtmap"),
                           "--out", str(tmp_path / "path.png")], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    before = float(lines[1].split("clearance ")[1].split(" m")[0])
    after = float(lines[2].split("clearance ")[1].split(" m")[0])
    assert after > 0.1 and after > before, done.stdout
    png = (tmp_path / "path.png").read_bytes()
    assert png.startswith(b"\x89PNG\r\n\x1a\n") and len(png) > 1000
