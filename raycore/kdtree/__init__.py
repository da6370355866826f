"""The SAH kd-tree and its frustum traversal (MLRTA, Reshetov et al. 2005):
build, camera packets, single rays."""
