"""glTF 2.0 meshes: loading and validation (``load_mesh``) into the typed :class:`MeshAsset`.

The asset contract lives in :mod:`psyop.mesh.asset`; drawing is ``psyop.rendering``'s job.
"""

from psyop.mesh.asset import AlphaMode, Filter, MeshAsset, MeshPart, MeshTexture, Wrap

__all__ = ["AlphaMode", "Filter", "MeshAsset", "MeshPart", "MeshTexture", "Wrap"]
