"""Ray casting core: build -> traverse -> shade, over flat float32/int32 arrays.

Layers, each importing only from the ones above it in this list (and from
its own package); tests/test_import_graph.py checks it:

  config.py    render settings, tolerances, block sizes
  jit/         numba presets, the kernel cache, threads, tile queue, work buffers
  geometry/    triangle tests, camera, sampling, shutter and lens, meshes, light rays
  images/      EXR and texture files
  grid/ kdtree/ bvh/   the three acceleration structures: build, traversal, drivers
  shading/     the visible surface, shading, the image's pixels
  accelerators.py, adaptive.py, sweep.py, instancing/   one surface over the
               structures, the error budget, the one-sweep shading pass,
               instanced worlds (two-level structures)
  structures.py  the per-frame owner of the structures (built or refit as asked)
  pass_scene.py  what one pass traces: structures and camera at its time and lens
  frame.py     one frame, phase by phase

Nothing here imports `anim` or `cli`.
"""
# the package's version: pyproject.toml, `frustrace --version` and the EXR headers read it here
__version__ = "0.1.0"
