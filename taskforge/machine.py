"""The machine a result was measured on, recorded beside every benchmark's and sweep's numbers:
speed on these machines varies several-fold, so a number without its machine says little."""

from __future__ import annotations

import os
import platform
from pathlib import Path
from typing import Any


def machine() -> dict[str, Any]:
    """CPU model, core count, Python, platform, and `TASKFORGE_MACHINE` (a label you set)."""
    cpu = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "host_label": os.environ.get("TASKFORGE_MACHINE", "dev container (2 cores, no GPU)"),
    }
