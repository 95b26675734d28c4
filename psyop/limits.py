"""Limits shared by protocol validation and the renderer, so that a protocol that validates renders.

``MAX_PRIMITIVES``: the most primitives one rendered scene may hold (the fragment shader's
uniform arrays are sized by it, psyop.rendering.shaders). Validation
(psyop.protocol.semantics) counts what each phase's scene expands to
(psyop.protocol.primitive_count) and refuses a protocol over it, with the scene item's file:line.

The glTF limits (``MAX_MESH_FILE_BYTES``, ``MAX_DATA_URI_BYTES``, ``MAX_MESH_TRIANGLES``,
``MAX_TEXTURE_SIDE_PX``) are enforced by psyop.mesh.load at load time, which validation runs;
``MAX_IMAGE_FILE_BYTES`` and ``MAX_TEXTURE_SIDE_PX`` also bound image surfaces (psyop.images).
"""

from __future__ import annotations

MAX_PRIMITIVES = 128

# ---- glTF meshes (psyop.mesh.load) ------------------------------------------------------------
#: the largest model file psyop reads: a ``.glb``, a ``.gltf``, each ``.bin`` and each image it names
#: (the dining room is under 1 MB; a 1M-triangle benchmark model about 40 MB)
MAX_MESH_FILE_BYTES = 128 << 20
#: the largest ``data:`` URI inside a ``.gltf`` (base64 text, a third larger than its bytes); larger
#: buffers or images belong in a ``.bin``/image file or a ``.glb``
MAX_DATA_URI_BYTES = 16 << 20
#: the most triangles one mesh item (one file, or one node of it) may hold
MAX_MESH_TRIANGLES = 2_000_000
#: the largest side of a base-colour texture, in texels (GPUs guarantee 16384; 8192 keeps an
#: RGBA float32 upload at 1 GiB at most)
MAX_TEXTURE_SIDE_PX = 8192
#: the largest image file psyop reads as a texture (an image surface or a glTF model's image)
MAX_IMAGE_FILE_BYTES = 128 << 20
