"""Memory the machine has free, so that work which would not fit is
refused with one line (exit 2) before it starts, not killed half way."""
from anim.errors import SceneError

# bytes a triangle of a frame costs at scale, all structures included:
# 218 measured on the 10M-triangle torus (docs/performance.md, Scale)
TRIANGLE_BYTES = 220


def available_bytes():
    """MemAvailable of /proc/meminfo (None where there is none)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def status_bytes(field):
    """A memory figure of /proc/self/status (VmHWM: peak resident, VmRSS: now), in bytes (0 where there is none)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


# the process before any scene: the interpreter and the libraries imported so far
BASE_RSS = status_bytes("VmRSS")


def peak_report(n_triangles, key_bytes):
    """{peak_rss_bytes, bytes_per_triangle}: this process's peak resident
    memory, and what it holds a triangle beyond the process before any
    scene (BASE_RSS) and the keyframes as stored (key_bytes)."""
    peak = status_bytes("VmHWM")
    return {"peak_rss_bytes": peak,
            "bytes_per_triangle": round((peak - BASE_RSS - key_bytes) / max(n_triangles, 1), 1) if peak else None}


def size_text(n_bytes) -> str:
    return f"{n_bytes / 1024 ** 3:.1f} GiB" if n_bytes >= 1024 ** 3 else f"{n_bytes / 1024 ** 2:.0f} MiB"


def check_copies(n_triangles, what, scene_path, key):
    """SceneError when copies that make n_triangles triangles would not fit:
    instances are made into the frame's triangles (two-level structures,
    one copy of each prototype, are not built yet)."""
    available = available_bytes()
    need = n_triangles * TRIANGLE_BYTES
    if available is not None and need > 0.9 * available:
        raise SceneError(scene_path, key, f"{what} make {n_triangles:,} triangles, about {size_text(need)} to render "
                                          f"(copies are made into the frame's triangles); {size_text(available)} "
                                          "are available")
