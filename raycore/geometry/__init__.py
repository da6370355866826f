"""What rays are made of and meet: the watertight triangle test, the camera
and its rays, sample patterns, shutter and lens positions, mesh gathering
and vertex normals, and shadow rays to lights in light-space order."""
