"""Animation: keyframe tracks in scene JSON, per-frame rendering, movies and distributed
rendering.
"""

#: frame file formats of ``voxwarp animate`` and their suffixes (here, so that the command
#: line offers them without loading the renderer)
FRAME_FORMATS: dict[str, str] = {"png": ".png", "exr": ".exr"}
