"""Rendering an animation: a scene file in, EXR frames and stats.json out.

settings (scene -> raycore tables) -> renderer (one frame at time t) ->
job (frames, claims, writes) -> stats (stats.json, fps). The command line
(cli/) only parses options and prints tables.
"""
