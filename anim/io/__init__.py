"""The file readers: meshes (trimesh, the binary mesh cache), glTF 2.0 with
its animations, and USD stages (usd-core)."""
