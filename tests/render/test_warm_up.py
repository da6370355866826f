"""warm_up (anim/render/warm_up.py) compiles every kernel the frame loop
uses, so that no compile time leaks into a frame's phases (issue 20: a
cold first run reported write_ms 731 and shade_ms 945 for frames 0 and 1).
Checked in a fresh process per configuration: a specialisation that
appears after warm_up is one the frames would have compiled."""
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "anim" / "builtin" / "demo" / "anim.yaml"


@pytest.mark.parametrize("overrides", ["{}",
                                       # every pass at its own time and lens point
                                       "dict(spp=4, accel='bvh', aovs=('N', 'P', 'id'), shutter=0.5, aperture_radius=0.02)",
                                       # 0.05: few pixels stay above the budget, so a group
                                       # of passes shades several passes' samples at once
                                       "dict(max_error=0.05, accel='kdtree')"])
def test_no_kernel_compiles_after_the_warm_up(overrides):
    out = subprocess.run([sys.executable, str(ROOT / "tests" / "warm_check.py"), str(DEMO), overrides],
                         capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert "NEW {}" in out.stdout, out.stdout
