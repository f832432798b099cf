"""Machine description recorded beside every timing (benchmarks, run summaries)."""

from __future__ import annotations

import os
import platform
import subprocess
from importlib.metadata import version


def machine() -> str:
    """CPU model, core count and Python/MuJoCo versions, for the benchmark record (MuJoCo's
    from its installed metadata: describing the host imports no MuJoCo)."""
    cpu = platform.processor() or platform.machine()
    try:
        out = subprocess.run(["lscpu"], capture_output=True, text=True, check=True).stdout
        for line in out.splitlines():
            if line.startswith("Model name:"):
                cpu = line.split(":", 1)[1].strip()
    except (OSError, subprocess.CalledProcessError):
        pass
    return (f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"MuJoCo {version('mujoco')}")
