"""The Gaussian Morphing Avatar: per-face features, decoders, the morphed mesh layer, surfel bindings,
posing, and the ``.gma`` file.

    from gma.avatar import Avatar
    avatar = Avatar.load("me.gma")            # body model loaded from the id in the file
    dec = avatar.decode()                     # DecodedAvatar: vertex offsets, SurfelBinding, colours
    renderer = AvatarRenderer(ctx, avatar)    # GPU posing + rendering (gma.avatar.gpu)
"""

from gma.avatar.avatar import FORMAT_VERSION, Avatar, AvatarFileError
from gma.avatar.config import ABLATIONS, AvatarConfig
from gma.avatar.model import AvatarModel, DecodedAvatar
from gma.avatar.posing import pose_surfels


def open_view_source(ctx, path):
    """The viewer's adapter (``gma view avatar.gma``): a ``gma.view.BodySource`` showing the avatar."""
    from gma.avatar.gpu import open_view_source as _open

    return _open(ctx, path)


__all__ = [
    "ABLATIONS",
    "FORMAT_VERSION",
    "Avatar",
    "AvatarConfig",
    "AvatarFileError",
    "AvatarModel",
    "DecodedAvatar",
    "open_view_source",
    "pose_surfels",
]
