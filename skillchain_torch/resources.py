"""What this machine has for a run: memory available now, and whether a torch device exists.

Both the trainer's config check (:meth:`~skillchain_torch.trainers.TrainConfig.validate`) and
the collision grid's size check (:func:`~skillchain_torch.envs.pinball.grid.check_grid_size`)
refuse work that cannot fit before allocating anything; they read the machine here.

Example:
    >>> available_memory("cpu") is None or available_memory("cpu") > 0
    True
    >>> device_problem("cpu") is None, "meta" in device_problem("meta")
    (True, True)
    >>> format_bytes(3 * 2**30)
    '3.0 GiB'
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["available_memory", "device_problem", "format_bytes"]


def format_bytes(n: float) -> str:
    """``n`` bytes in B, KiB, MiB, ... (one decimal above bytes)."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        if n < 1024 or unit == "EiB":
            return f"{n:,.0f} {unit}" if unit == "B" else f"{n:,.1f} {unit}"
        n /= 1024
    raise AssertionError  # pragma: no cover


def available_memory(device: str = "cpu") -> int | None:
    """Bytes of memory a new run can use now: ``MemAvailable`` (and the cgroup's limit) on
    Linux, ``psutil`` elsewhere, the free CUDA memory for a CUDA device; ``None`` if unknown."""
    import torch

    dev = torch.device(device)
    if dev.type == "cuda":
        try:
            return int(torch.cuda.mem_get_info(dev)[0])
        except Exception:  # noqa: BLE001 - unknown is fine: no check
            return None
    if dev.type != "cpu":
        return None
    found = []
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    found.append(int(line.split()[1]) * 1024)
    except (OSError, ValueError, IndexError):
        pass
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        used = Path("/sys/fs/cgroup/memory.current").read_text().strip()
        if limit != "max":
            found.append(max(int(limit) - int(used), 0))
    except (OSError, ValueError):
        pass
    if not found:
        try:
            import psutil

            found.append(int(psutil.virtual_memory().available))
        except Exception:  # noqa: BLE001 - no psutil: try sysconf
            try:
                found.append(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
            except (AttributeError, ValueError, OSError):
                return None
    return min(found)


def device_problem(device: str) -> str | None:
    """Why ``device`` is not a torch device this machine has (one line), or ``None``."""
    import torch

    try:
        dev = torch.device(device)
    except (RuntimeError, ValueError, TypeError):
        return f"device must be a torch device such as cpu, cuda or cuda:0, got {device!r}"
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            build = (f"CUDA {torch.version.cuda}" if torch.version.cuda
                     else "a CPU-only build")  # fmt: skip
            return (f"device {device!r} is not available: torch {torch.__version__} ({build}) "
                    f"sees no CUDA device; use cpu")
        count = torch.cuda.device_count()
        if dev.index is not None and dev.index >= count:
            return (f"device {device!r} is not available: this machine has {count} CUDA "
                    f"device(s), cuda:0 to cuda:{count - 1}")
    elif dev.type == "meta":
        return "device 'meta' holds no data (shapes only); use cpu or cuda"
    elif dev.type != "cpu":
        try:
            torch.zeros(1, device=dev)
        except Exception as err:  # noqa: BLE001 - torch raises many types for absent devices
            text = " ".join(str(err).split()) or type(err).__name__
            first = text.split(". ")[0][:120]
            return f"device {device!r} is not available here ({first})"
    return None
