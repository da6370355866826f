"""Image files at the edge of the core: EXR frames (OpenImageIO, the OpenEXR
bindings, a faster zip encoder), textures, half floats."""
