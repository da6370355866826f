"""Scene file -> meshes -> vertex positions at time t, and the library above
the ray casting core.

  anim/*.py     the scene (schema.py, scene.py) and its motion: splines and
                TRS tracks, skeletons, rigid batches, area lights, materials
  io/           the file readers (meshes, the mesh cache, glTF, USD)
  builtin/      the procedural built-in scenes and their exact motion
  render/       the render library: a scene renderer, the frame loop, the
                output files, stats, the warm-up, the Dask cluster
  measure/      the measurements: bench, peers, compare, error studies
"""
