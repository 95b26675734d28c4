"""Which primitives exact geometry says must be hidden in a frame (float64, no GPU).

A primitive A is *meant to be hidden* from a centre of projection P when one other convex
primitive B covers it: the ray from P through every sample of A's outline (and its centre)
hits B inside, and B wins the hit by the renderer's rule (nearer, or coplanar within
:data:`~psyop.rendering.scene.COPLANAR_RELATIVE_DEPTH` and listed later; a primitive at optical
infinity is behind every finite one). The image of a planar convex primitive is convex, so B's
image then contains A's. This is the study's design rule (e.g. the detection stimulus: the red
back disc is hidden behind the equal-angle noise disc in conventional mode and at level 0 D in
every mode), derived from the geometry rather than declared. Primitives with a sinusoidal border
(not convex) are neither checked nor used as occluders.
"""

from __future__ import annotations

import numpy as np

from psyop.rendering.scene import COPLANAR_RELATIVE_DEPTH, Primitive, Shape

OUTLINE_SAMPLES = 64
INSIDE_TOLERANCE = 1e-7  # relative, on the implicit edge function (exact rim contact counts as inside)


def outline_local(shape: Shape) -> np.ndarray:
    """(n, 2) local (a, b) samples of a primitive's outline, plus its centre."""
    theta = np.linspace(0.0, 2.0 * np.pi, OUTLINE_SAMPLES, endpoint=False)
    if shape is Shape.DISC:
        pts = np.stack([np.cos(theta), np.sin(theta)], axis=-1)
    else:
        s = np.linspace(-1.0, 1.0, OUTLINE_SAMPLES // 4, endpoint=False)
        one = np.ones_like(s)
        pts = np.concatenate([np.stack([s, -one], -1), np.stack([one, s], -1), np.stack([-s, one], -1),
                              np.stack([-one, -s], -1)])
    return np.concatenate([pts, [[0.0, 0.0]]])


def _axes(p: Primitive) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.array(p.centre_m), np.array(p.half_u_m), np.array(p.half_v_m)


def hits(prim: Primitive, origin_m: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(inside, t) of rays ``origin + t * direction`` against a primitive without border.
    ``t`` is inf for a primitive at optical infinity (its hits are directions)."""
    c, u, v = _axes(prim)
    n = np.cross(u, v)
    rel = c if prim.at_infinity else c - origin_m
    denom = directions @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (rel @ n) / denom
        x = t[:, None] * directions - rel
        a = x @ u / (u @ u)
        b = x @ v / (v @ v)
    g = np.hypot(a, b) if prim.shape is Shape.DISC else np.maximum(np.abs(a), np.abs(b))
    inside = np.isfinite(t) & (t > 0) & (g <= 1.0 + INSIDE_TOLERANCE)
    return inside, (np.full_like(t, np.inf) if prim.at_infinity else t)


def hidden_by(primitives: tuple[Primitive, ...], centre_of_projection_m: np.ndarray) -> dict[int, int]:
    """{index of A: index of the primitive B that covers it} for every primitive that exact
    geometry says is wholly hidden from ``centre_of_projection_m``."""
    cop = np.asarray(centre_of_projection_m, dtype=np.float64)
    out: dict[int, int] = {}
    for ia, a in enumerate(primitives):
        if a.border is not None:
            continue
        c, u, v = _axes(a)
        local = outline_local(a.shape)
        points = c + local[:, :1] * u + local[:, 1:] * v
        directions = points if a.at_infinity else points - cop
        t_a = np.inf if a.at_infinity else 1.0
        for ib, b in enumerate(primitives):
            if ib == ia or b.border is not None:
                continue
            inside, t_b = hits(b, cop, directions)
            if a.at_infinity:
                wins = inside & (np.isfinite(t_b) | (ib > ia))
            else:
                tol = COPLANAR_RELATIVE_DEPTH * t_a
                wins = inside & ((t_b < t_a - tol) | ((np.abs(t_b - t_a) <= tol) & (ib > ia)))
            if np.all(wins):
                out[ia] = ib
                break
    return out
