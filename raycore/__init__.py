"""Ray casting core: grid build -> packet traversal -> shading -> EXR output.

Kernels see only flat float32/int32 arrays; nothing here imports `anim` or `cli`.
"""
