"""The per-frame BVH: node layout, binned-SAH build, refit, packet and
single-ray traversal, and the scene's trees (one per moving object under a
top level)."""
