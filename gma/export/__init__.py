"""Exporting avatars to formats other tools read: posed surfels as a Gaussian-splat PLY (3DGS or 2DGS
layout) and the posed, morphed body mesh with surfel colours (GLB, OBJ, PLY through trimesh).

    from gma.export import export_poses, posed_splats, write_splats, posed_mesh
"""

from gma.export.mesh import posed_mesh, write_mesh
from gma.export.poses import NAMED_POSES, ExportPose, export_poses
from gma.export.splats import posed_splats, write_splats

__all__ = ["NAMED_POSES", "ExportPose", "export_poses", "posed_mesh", "posed_splats", "write_mesh", "write_splats"]
