"""Tiles handed to the cores with dynamic load balancing.

One worker per thread (jit/launch.py or thread_pool.on_threads starts them);
each allocates its scratch once and then pulls work items (camera tiles,
ray packets, chunks of single rays) from one queue, a shared atomic counter
(new_queue, next_tile), until none are left, so a thread that drew cheap
items (sky) takes more of them. Every traversal, grid, kd-tree and BVH,
pulls its work this way. Tiles are square, a multiple of the packet size,
and many more than the threads.
"""
import numpy as np

from raycore.jit.presets import fetch_add, helper, kernel


def new_queue():
    """An empty work queue: the counter next_tile advances, one for all the
    workers of a call (jit/launch.py or thread_pool.on_threads starts them)."""
    return np.zeros(1, np.int64)


@helper
def next_tile(queue, n_items):
    """The next unclaimed item of 0..n_items-1, or -1 when all are taken
    (atomic: every item goes to exactly one thread)."""
    item = fetch_add(queue, 0, 1)
    return item if item < n_items else -1


def tile_size_for(width: int, height: int, packet: int, threads: int) -> int:
    """Largest tile (packet multiple, <= 64 px, >= packet) that still gives at
    least 16 tiles per thread, so the queue can balance the load."""
    size = max(packet, 64 // packet * packet)
    while size > packet:
        n_tiles = -(-width // size) * -(-height // size)
        if n_tiles >= 16 * max(threads, 1):
            break
        size -= packet
    return size


@kernel
def tile_count(width, height, tile_size):
    """(tiles per row, tiles in all) of an image cut into square tiles."""
    tiles_x = (width + tile_size - 1) // tile_size
    return tiles_x, tiles_x * ((height + tile_size - 1) // tile_size)


@kernel
def tile_corner(tile, tiles_x, tile_size):
    """Top-left pixel of tile number `tile` (row-major over the tiles)."""
    return (tile % tiles_x) * tile_size, (tile // tiles_x) * tile_size
