"""The Gaussian Morphing Avatar: per-face features, decoders, the morphed mesh layer, surfel bindings,
posing, and the ``.gma`` file.

    from gma.avatar import Avatar
    avatar = Avatar.load("me.gma")            # body model loaded from the id in the file
    dec = avatar.decode()                     # DecodedAvatar: vertex offsets, SurfelBinding, colours
    renderer = AvatarRenderer(ctx, avatar)    # GPU posing + rendering (gma.avatar.gpu)
"""

import importlib

# Exports load on first use (PEP 562), so that the light ``gma.avatar.config`` (which ``gma --help``
# needs to build the fit options) does not pull torch in through this package's __init__.
_EXPORTS = {
    "FORMAT_VERSION": "gma.avatar.avatar", "Avatar": "gma.avatar.avatar", "AvatarFileError": "gma.avatar.avatar",
    "ABLATIONS": "gma.avatar.config", "AvatarConfig": "gma.avatar.config",
    "AvatarModel": "gma.avatar.model", "DecodedAvatar": "gma.avatar.model",
    "pose_surfels": "gma.avatar.posing",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'gma.avatar' has no attribute {name!r}")
