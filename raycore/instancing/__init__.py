"""Instanced worlds as two-level structures: the prototypes' trees, a top
level over the instances rebuilt every frame, rays carried into each
instance's space, and the seen triangles placed in the world for shading."""
