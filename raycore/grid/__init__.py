"""The per-frame uniform grid and Coherent Grid Traversal (Wald et al. 2006):
build (binning, the incremental grid), the frustum walk, single-ray DDA,
camera packets and their layout, and the drivers that hand tiles to cores."""
