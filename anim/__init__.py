"""Scene file -> meshes -> vertex positions at time t."""
