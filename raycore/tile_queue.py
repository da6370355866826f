"""Tiles handed to the cores with dynamic load balancing.

One prange iteration per thread; each thread allocates its packet scratch once
and then pulls tile (or packet) indices from a shared atomic counter
(_jit.fetch_add) until none are left, so a thread that drew cheap tiles (sky)
takes more of them. Tiles are square, a multiple of the packet size, and many
more than the threads.
"""
from ._jit import kernel


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
