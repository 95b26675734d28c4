"""Limits shared by protocol validation and the renderer, so that a protocol that validates renders.

``MAX_PRIMITIVES``: the most primitives one rendered scene may hold (the fragment shader's
uniform arrays are sized by it, psyop.rendering.shaders). Validation
(psyop.protocol.semantics) counts what each phase's scene expands to
(psyop.protocol.primitive_count) and refuses a protocol over it, with the scene item's file:line.
"""

from __future__ import annotations

MAX_PRIMITIVES = 128
