"""glTF 2.0 meshes: loading and validation (``load_mesh``, ``MeshFiles``) into the typed :class:`MeshAsset`.

The asset contract lives in :mod:`psyop.mesh.asset`; drawing is ``psyop.rendering``'s job.
"""

from psyop.mesh.asset import AlphaMode, Filter, MeshAsset, MeshPart, MeshTexture, Wrap
from psyop.mesh.load import MeshFiles, load_mesh

__all__ = ["AlphaMode", "Filter", "MeshAsset", "MeshFiles", "MeshPart", "MeshTexture", "Wrap", "load_mesh"]
