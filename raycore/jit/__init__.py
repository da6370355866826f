"""The runtime under every kernel: numba presets (presets.py), the on-disk
kernel cache made stale by any kernel source (kernel_cache.py), threads and
the dynamic tile queue, native launches, reusable work buffers, counters and
small vector helpers."""
