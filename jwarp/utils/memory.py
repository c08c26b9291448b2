"""Memory estimates: refuse work that cannot fit in memory before starting it.

The CLI (``plan``/``ik`` batch sizes, ``--world simplex:cells=...``) and the world spec
parser estimate what a job needs from its sizes and raise :class:`MemoryError` with the
figure (``"a 100000 x 100000 grid needs about 4.0 TB of memory, more than the 21 GB
available"``) instead of starting an allocation that fails (or swaps) later.
"""

from __future__ import annotations

import os

__all__ = ["available_memory", "format_bytes", "check_memory"]


def available_memory() -> int | None:
    """Memory available to new allocations [bytes]: Linux ``MemAvailable``, else the free
    physical pages; None where neither is known (then nothing is refused)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_AVPHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return None


def format_bytes(n: float) -> str:
    """``n`` bytes as ``"512 B"``, ``"3.2 GB"``, ``"8.0 TB"``, ``"4.1e+06 TB"`` (decimal units)."""
    n = float(n)
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if n < 1000 or unit == "TB":
            break
        n /= 1000
    if unit == "B":
        return f"{n:.0f} B"
    return f"{n:.1f} {unit}" if n < 1e4 else f"{n:.2g} {unit}"


def check_memory(need: float, what: str, hint: str = "") -> None:
    """MemoryError ``"<what> needs about <need> of memory, more than the <have> available
    [; hint]"`` when the estimate ``need`` [bytes] exceeds :func:`available_memory`."""
    have = available_memory()
    if have is not None and need > have:
        raise MemoryError(f"{what} needs about {format_bytes(need)} of memory, more than the "
                          f"{format_bytes(have)} available" + (f"; {hint}" if hint else ""))
