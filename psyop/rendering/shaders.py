"""GLSL for the full-screen ray-casting pass (OpenGL 4.5 core is not required: 4.1 suffices).

Every pixel casts rays from the centre of projection (the origin: everything is camera-relative)
through the analytic primitives; the nearest hit wins per sample. Hits within a relative
``COPLANAR_REL`` of each other in distance are coplanar and the later-listed primitive wins.
A primitive whose centre has w = 0 (``u_centre[i].w``) lies at optical infinity: its centre is
a direction (not made camera-relative), it is not clipped by near/far, and its hit distance is
``T_INFINITY``, behind every finite hit. The anti-aliasing variant is
chosen at compile time with one of the ``AA_*`` defines:

``AA_NONE``        one sample at the pixel centre.
``AA_SUPERSAMPLE`` a regular SxS grid in every pixel.
``AA_MSAA``        one ray per MSAA sample (sample-rate shading at ``gl_SamplePosition``), so the
                   sample pattern is exactly the hardware MSAA pattern; resolved afterwards.
``AA_ADAPTIVE``    one sample, or an SxS grid where a primitive edge passes within
                   ``u_edge_margin_px`` of the pixel centre (edge distance = the primitive's
                   implicit edge function divided by its screen-space gradient, from the 2x2
                   quad's dFdx/dFdy, so detecting edges costs no extra rays).
                   Two-pass form (the default, ``RenderSettings.adaptive_two_pass``): the first
                   pass shades every pixel with one ray and writes depth 0 at edge pixels; the
                   second, ``AA_EDGE_PASS``, is drawn with depth test GREATER so only those
                   pixels are shaded, on the SxS grid, testing only the primitives whose
                   CPU-computed screen box overlaps the pixel. Non-edge pixels thus never pay for
                   the supersampling code (which a SIMD rasteriser such as llvmpipe would
                   otherwise execute masked in every pixel).
                   Effort per primitive: an edge pixel gets the largest ``edge_samples_per_axis``
                   of the primitives that can reach it (a primitive's own, or ``u_samples`` when it
                   has none), so straight background edges (a room's corners) take a few samples
                   and the stimulus edges the full grid.
"""

from __future__ import annotations

from enum import Enum

from psyop.limits import MAX_PRIMITIVES  # shared with protocol validation
from psyop.rendering.scene import COPLANAR_RELATIVE_DEPTH, OUTPUT_TABLE_ROW

TEXELS_PER_PRIMITIVE = 7


class AntiAliasing(str, Enum):
    NONE = "none"
    MSAA = "msaa"
    SUPERSAMPLE = "supersample"
    ADAPTIVE = "adaptive"


VERTEX_SHADER = """
#version 410 core
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

FRAGMENT_TEMPLATE = """
#version 410 core
#define MAX_PRIMS %(max_prims)d
#define %(aa_define)s
const float TWO_PI = 6.28318530717958647692;
const float T_INFINITY = 1e30;             // hit distance of a primitive at optical infinity
const float COPLANAR_REL = %(coplanar)g;  // relative depth difference treated as coplanar

// A hit at t replaces the best so far when it is nearer or coplanar (later-listed wins).
bool replaces(float t, float best_t) { return t <= best_t * (1.0 + COPLANAR_REL); }

layout(std140) uniform Centres { vec4 u_centre[MAX_PRIMS]; };
#if defined(AA_EDGE_PASS) || defined(ADAPTIVE_CULL)
layout(std140) uniform Bounds { vec4 u_bound[MAX_PRIMS]; };  // screen boxes (x0, y0, x1, y1), px, y down
#endif
uniform sampler2D u_prims;          // static per-primitive data, TEXELS_PER_PRIMITIVE x n
uniform sampler2DArray u_textures;  // texture layers, fetched nearest-neighbour
uniform sampler2D u_aperture;       // screen-fixed coverage (1 = visible), computed once per eye
uniform mat3 u_ray;                 // direction = u_ray * (u, v, 1), u right, v down
uniform vec2 u_size_px;
uniform int u_n_prims;
uniform int u_samples;              // per axis, for ADAPTIVE and SUPERSAMPLE
uniform float u_edge_margin_px;
uniform float u_near_m;
uniform float u_far_m;
uniform vec3 u_background;
uniform vec3 u_aperture_colour;

out vec4 frag_colour;

#ifdef MESH_LAYER
// The mesh pass's multisampled target (psyop.rendering.mesh_pass): premultiplied colour and 1 / distance
// from the centre of projection per sample (0 = no mesh). A ray sample shows its analytic hit where it is
// nearer than the pixel's nearest mesh sample, else the pixel's resolved mesh colour over it.
uniform sampler2DMS u_mesh_colour;
uniform sampler2DMS u_mesh_inv_distance;
uniform int u_mesh_samples;
vec4 mesh_rgba = vec4(0.0);
float mesh_inv = 0.0;
void load_mesh_pixel(ivec2 fc) {
    for (int s = 0; s < u_mesh_samples; ++s) {
        mesh_rgba += texelFetch(u_mesh_colour, fc, s);
        mesh_inv = max(mesh_inv, texelFetch(u_mesh_inv_distance, fc, s).r);
    }
    mesh_rgba /= float(u_mesh_samples);
}
vec3 mesh_over(vec3 colour, float dist) {
    return (dist * mesh_inv < 1.0) ? colour : mesh_rgba.rgb + (1.0 - mesh_rgba.a) * colour;
}
#define MESH_OVER(c, dist) mesh_over(c, dist)
#else
#define MESH_OVER(c, dist) (c)
#endif

struct Hit { bool plane; bool inside; float t; float a; float b; float g; };

vec4 P(int i, int k) { return texelFetch(u_prims, ivec2(k, i), 0); }

vec3 ray_at(vec2 xy_px) { return u_ray * vec3(xy_px / u_size_px, 1.0); }

Hit intersect(int i, vec3 d) {
    Hit h; h.plane = false; h.inside = false; h.t = 0.0; h.a = 0.0; h.b = 0.0; h.g = 1e30;
    vec4 p0 = P(i, 0); vec4 p1 = P(i, 1);
    vec3 hu = p0.xyz; vec3 hv = p1.xyz; vec3 c = u_centre[i].xyz; bool at_inf = u_centre[i].w < 0.5;
    vec3 n = cross(hu, hv);
    float denom = dot(d, n);
    float num = dot(c, n);
    if (abs(denom) <= 1e-30 * length(n) * length(d)) return h;
    float t = num / denom;
    if (!(t > 0.0) || isinf(t)) return h;
    vec3 x = t * d;
    float depth = -x.z;
    if (!at_inf && (depth < u_near_m || depth > u_far_m)) return h;
    vec3 r = x - c;
    float a = dot(r, hu) / dot(hu, hu);
    float b = dot(r, hv) / dot(hv, hv);
    float g = (p0.w < 0.5) ? length(vec2(a, b)) - 1.0 : max(abs(a), abs(b)) - 1.0;
    vec4 p5 = P(i, 5);
    if (p5.x > 0.5) {
        vec4 p6 = P(i, 6);
        float border = p6.x + p5.y * sin(TWO_PI * p5.z * 0.5 * (b + 1.0) + p5.w);
        g = max(g, -p6.y * (a - border));  // keep side * (a - border) >= 0
    }
    h.plane = true; h.t = at_inf ? T_INFINITY : t; h.a = a; h.b = b; h.g = g; h.inside = g <= 0.0;
    return h;
}

// A grating (psyop.rendering.scene.Grating): p2 = (mean, amplitude, phase in cycles, square?), p3 = (cycles per
// surface degree along a and b, surface degrees per local unit along a and b), p4 = (window kind, its two numbers).
// The cycle count is reduced with fract() before sin(), so the phase keeps float32's relative precision.
float square_triangle(float c) { float f = fract(c); return f < 0.5 ? f : 1.0 - f; }

vec3 shade_grating(int i, vec4 p2, float a, float b, float footprint) {
    vec4 p3 = P(i, 3); vec4 p4 = P(i, 4);
    vec2 xy = vec2(a * p3.z, b * p3.w);
    float cyc = xy.x * p3.x + xy.y * p3.y;
    float c = fract(cyc) + p2.z;
    float s;
    if (p2.w < 0.5) {
        s = sin(TWO_PI * c);
    } else {
        // box filter along the modulation over the pixel footprint (local units per pixel): half-width in cycles
        float h = 0.5 * footprint * (abs(p3.x * p3.z) + abs(p3.y * p3.w));
        s = h > 1e-6 ? (square_triangle(c + h) - square_triangle(c - h)) / (2.0 * h) : (fract(c) < 0.5 ? 1.0 : -1.0);
    }
    float w = 1.0;
    if (p4.x > 1.5) {
        w = 0.5 + 0.5 * cos(3.14159265358979 * clamp((length(xy) - p4.y) / p4.z, 0.0, 1.0));
    } else if (p4.x > 0.5) {
        w = exp(-0.5 * dot(xy, xy) / (p4.y * p4.y));
    }
    return vec3(p2.x + p2.y * w * s);
}

vec3 shade(int i, float a, float b, float footprint) {
    vec4 p1 = P(i, 1); vec4 p2 = P(i, 2);
    int kind = int(p1.w + 0.5);
    if (kind == 0) return p2.rgb;
    if (kind == 3) return shade_grating(i, p2, a, b, footprint);
    vec4 p4 = P(i, 4);
    if (kind == 1) {
        vec2 st = fract(vec2(a * 0.5 + 0.5, 0.5 - b * 0.5) * p4.z);
        ivec2 texel = clamp(ivec2(floor(st * p4.xy)), ivec2(0), ivec2(p4.xy) - 1);
        return texelFetch(u_textures, ivec3(texel, int(p2.w + 0.5)), 0).rgb;
    }
    vec4 p3 = P(i, 3);
    vec2 s = (vec2(a, b) * 0.5 + 0.5) * p3.w;
    vec2 dist = abs(fract(s + 0.5) - 0.5);
    float half_w = 0.5 * p4.w;
    float fw = max(footprint * 0.5 * p3.w, 1e-6);
    vec2 cov = clamp((half_w - dist) / fw + 0.5, 0.0, 1.0);
    float line = max(cov.x, cov.y);
    return mix(p2.rgb, p3.rgb, line);
}

vec3 sample_colour(vec3 d, float footprint) {
    int best = -1; float best_t = 1e38; float ba = 0.0; float bb = 0.0;
    for (int i = 0; i < u_n_prims; ++i) {
        Hit h = intersect(i, d);
        if (h.inside && replaces(h.t, best_t)) { best = i; best_t = h.t; ba = h.a; bb = h.b; }
    }
    return MESH_OVER(best < 0 ? u_background : shade(best, ba, bb, footprint), best_t * length(d));
}

vec3 grid_colour(vec2 corner_px, int n) {
    vec3 acc = vec3(0.0);
    float inv = 1.0 / float(n);
    for (int j = 0; j < n; ++j)
        for (int k = 0; k < n; ++k)
            acc += sample_colour(ray_at(corner_px + (vec2(k, j) + 0.5) * inv), 0.0);
    return acc * inv * inv;
}

#if defined(AA_ADAPTIVE) || defined(AA_EDGE_PASS)
#define MAX_RELEVANT 16
// Primitive data of the pixel's relevant primitives, cached in registers for the sample loop.
struct Cached { int index; vec3 c; vec3 n; vec3 hu2; vec3 hv2; float num; float rect; vec4 border; vec2 side;
                bool at_inf; int samples; };
Cached relevant[MAX_RELEVANT];
int n_relevant = 0;

void cache_primitive(int i) {
    vec4 p0 = P(i, 0); vec4 p1 = P(i, 1);
    Cached k;
    k.index = i; k.c = u_centre[i].xyz; k.n = cross(p0.xyz, p1.xyz);
    k.hu2 = p0.xyz / dot(p0.xyz, p0.xyz); k.hv2 = p1.xyz / dot(p1.xyz, p1.xyz);
    vec4 p6 = P(i, 6);
    k.num = dot(k.c, k.n); k.rect = p0.w; k.border = P(i, 5); k.side = p6.xy; k.at_inf = u_centre[i].w < 0.5;
    k.samples = p6.z > 0.5 ? int(p6.z + 0.5) : u_samples;  // the primitive's edge effort (0: default)
    relevant[n_relevant++] = k;
}

// Samples per axis for a pixel: the largest effort among the primitives that can reach it, so
// an edge of a stimulus primitive gets the full grid and one between background primitives
// (e.g. room corners) only theirs.
int relevant_samples() {
    int n = 1;
    for (int r = 0; r < n_relevant; ++r) n = max(n, relevant[r].samples);
    return n;
}

// Like grid_colour, but only over the primitives that can be hit inside this pixel: those
// covering its centre or with an edge within the margin (no other one reaches the pixel).
vec3 grid_colour_relevant(vec2 corner_px, int n) {
    vec3 acc = vec3(0.0);
    float inv = 1.0 / float(n);
    for (int j = 0; j < n; ++j)
        for (int k = 0; k < n; ++k) {
            vec3 d = ray_at(corner_px + (vec2(k, j) + 0.5) * inv);
            int best = -1; float best_t = 1e38; float ba = 0.0; float bb = 0.0;
            for (int r = 0; r < n_relevant; ++r) {
                float t = relevant[r].num / dot(d, relevant[r].n);
                if (!(t > 0.0) || isinf(t)) continue;
                if (!replaces(relevant[r].at_inf ? T_INFINITY : t, best_t)) continue;
                vec3 x = t * d;
                if (!relevant[r].at_inf && (-x.z < u_near_m || -x.z > u_far_m)) continue;
                vec3 q = x - relevant[r].c;
                float a = dot(q, relevant[r].hu2);
                float b = dot(q, relevant[r].hv2);
                float g = (relevant[r].rect < 0.5) ? length(vec2(a, b)) - 1.0 : max(abs(a), abs(b)) - 1.0;
                vec4 bd = relevant[r].border;
                if (bd.x > 0.5)
                    g = max(g, -relevant[r].side.y
                               * (a - (relevant[r].side.x + bd.y * sin(TWO_PI * bd.z * 0.5 * (b + 1.0) + bd.w))));
                if (g <= 0.0) { best = relevant[r].index; best_t = relevant[r].at_inf ? T_INFINITY : t; ba = a; bb = b; }
            }
            acc += MESH_OVER(best < 0 ? u_background : shade(best, ba, bb, 0.0), best_t * length(d));
        }
    return acc * inv * inv;
}

#endif

void main() {
    ivec2 fc = ivec2(gl_FragCoord.xy);
    vec2 corner = vec2(float(fc.x), u_size_px.y - 1.0 - float(fc.y));  // top-left, y down
    vec3 colour;
#ifdef MESH_LAYER
    load_mesh_pixel(fc);
#endif
    float alpha = 1.0;  // 0.5 marks an adaptively supersampled (edge) pixel, for work accounting
#if defined(AA_NONE)
    colour = sample_colour(ray_at(corner + 0.5), 0.0);
#elif defined(AA_SUPERSAMPLE)
    colour = grid_colour(corner, u_samples);
#elif defined(AA_MSAA)
    vec2 sp = gl_SamplePosition;
    colour = sample_colour(ray_at(corner + vec2(sp.x, 1.0 - sp.y)), 0.0);
#elif defined(AA_EDGE_PASS)
    // Second pass of the two-pass adaptive sampler: only edge pixels get here (the depth test
    // rejects the others before shading). The primitives that can be hit inside the pixel are
    // those whose conservative screen box (CPU, per frame) overlaps the pixel, padded by 1 px.
    bool overflow = false;
    for (int i = 0; i < u_n_prims; ++i) {
        vec4 bd = u_bound[i];
        if (bd.x <= corner.x + 2.0 && bd.z >= corner.x - 1.0 && bd.y <= corner.y + 2.0 && bd.w >= corner.y - 1.0) {
            if (n_relevant < MAX_RELEVANT) cache_primitive(i); else overflow = true;
        }
    }
    colour = overflow ? grid_colour(corner, u_samples) : grid_colour_relevant(corner, relevant_samples());
    alpha = 0.5;
#else
    vec3 d0 = ray_at(corner + 0.5);
    bool edge = false;
    bool overflow = false;
    int best = -1; float best_t = 1e38; float ba = 0.0; float bb = 0.0; float fw = 0.0;
#if defined(ADAPTIVE_CULL)
    // Cull per aligned 4x4 pixel block (it holds whole 2x2 quads, so derivatives stay valid and
    // a SIMD rasteriser's lanes agree): a primitive whose screen box, padded by the margin and
    // 2 px of float32 slack, misses the block can neither cover nor have an edge near its pixels.
    ivec2 block = fc & ~3;
    vec2 block_lo = vec2(float(block.x), u_size_px.y - float(block.y) - 4.0);  // y down
    float pad = u_edge_margin_px + 2.0;
    int i = -1;
    while (true) {
        for (++i; i < u_n_prims; ++i) {
            vec4 bd = u_bound[i];
            if (bd.x <= block_lo.x + 4.0 + pad && bd.z >= block_lo.x - pad
                && bd.y <= block_lo.y + 4.0 + pad && bd.w >= block_lo.y - pad) break;
        }
        if (i >= u_n_prims) break;
#else
    for (int i = 0; i < u_n_prims; ++i) {
#endif
        // One ray per pixel; the neighbours' values come from the 2x2 pixel quad's screen-space
        // derivatives (uniform control flow: the loop bound is a uniform).
        Hit h0 = intersect(i, d0);
        float plane = h0.plane ? 1.0 : 0.0;
        float inside = h0.inside ? 1.0 : 0.0;
        float g = h0.plane ? clamp(h0.g, -1e6, 1e6) : 1e6;
        float gl = length(vec2(dFdx(g), dFdy(g)));
        float a = h0.plane ? clamp(h0.a, -1e6, 1e6) : 0.0;
        float b = h0.plane ? clamp(h0.b, -1e6, 1e6) : 0.0;
        vec2 dab = vec2(max(abs(dFdx(a)), abs(dFdy(a))), max(abs(dFdx(b)), abs(dFdy(b))));
        bool near_edge = fwidth(plane) > 0.0 || fwidth(inside) > 0.0
                         || (h0.plane && !(abs(h0.g) > u_edge_margin_px * gl));
        edge = edge || near_edge;
#if !defined(ADAPTIVE_TWO_PASS)
        if (near_edge || h0.inside) {
            if (n_relevant < MAX_RELEVANT) cache_primitive(i); else overflow = true;
        }
#endif
        if (h0.inside && replaces(h0.t, best_t)) {
            best = i; best_t = h0.t; ba = h0.a; bb = h0.b; fw = max(dab.x, dab.y);
        }
    }
    colour = MESH_OVER(best < 0 ? u_background : shade(best, ba, bb, fw), best_t * length(d0));
#if defined(ADAPTIVE_TWO_PASS)
    // First pass: one ray per pixel; edge pixels are marked in the depth buffer for the second.
    gl_FragDepth = edge ? 0.0 : 1.0;
#else
    if (edge) {
        colour = overflow ? grid_colour(corner, u_samples) : grid_colour_relevant(corner, relevant_samples());
        alpha = 0.5;
    }
#endif
#endif
    float ap = texelFetch(u_aperture, ivec2(fc.x, fc.y), 0).r;
    colour = mix(u_aperture_colour, colour, ap);
    if (any(isnan(colour)) || any(isinf(colour))) colour = u_background;
    frag_colour = vec4(clamp(colour, 0.0, 1.0), alpha);
}
"""


def fragment_shader(antialiasing: AntiAliasing, two_pass: bool = False, cull: bool = False,
                    meshes: bool = False) -> str:
    """The fragment shader source for one anti-aliasing variant.

    ``two_pass`` (adaptive only): the source of the first pass, which shades one ray per pixel
    and marks edge pixels in the depth buffer (0 = edge) instead of supersampling them in place;
    :func:`edge_pass_shader` is the second pass. ``cull`` (two-pass only): the first pass skips,
    per aligned 4x4 pixel block, the primitives whose screen box (uniform block ``Bounds``)
    cannot reach the block. ``meshes``: the variant that composites the mesh pass's target
    (``MESH_LAYER``); without it the source compiles to the analytic-only shader.
    """
    define = {
        AntiAliasing.NONE: "AA_NONE",
        AntiAliasing.MSAA: "AA_MSAA",
        AntiAliasing.SUPERSAMPLE: "AA_SUPERSAMPLE",
        AntiAliasing.ADAPTIVE: "AA_ADAPTIVE",
    }[AntiAliasing(antialiasing)]
    if two_pass and define == "AA_ADAPTIVE":
        define = "AA_ADAPTIVE\n#define ADAPTIVE_TWO_PASS" + ("\n#define ADAPTIVE_CULL" if cull else "")
    if meshes:
        define += "\n#define MESH_LAYER"
    return FRAGMENT_TEMPLATE % {"max_prims": MAX_PRIMITIVES, "aa_define": define, "coplanar": COPLANAR_RELATIVE_DEPTH}


def edge_pass_shader(meshes: bool = False) -> str:
    """Second pass of the two-pass adaptive sampler: SxS rays in the pixels the first pass marked
    (``meshes``: compositing the mesh pass, see :func:`fragment_shader`)."""
    define = "AA_EDGE_PASS" + ("\n#define MESH_LAYER" if meshes else "")
    return FRAGMENT_TEMPLATE % {"max_prims": MAX_PRIMITIVES, "aa_define": define,
                                "coplanar": COPLANAR_RELATIVE_DEPTH}


#: The 8 x 8 Bayer matrix (recursive ordered-dither indices 0..63), row by row.
BAYER_8X8: tuple[int, ...] = (
    0, 32, 8, 40, 2, 34, 10, 42, 48, 16, 56, 24, 50, 18, 58, 26,
    12, 44, 4, 36, 14, 46, 6, 38, 60, 28, 52, 20, 62, 30, 54, 22,
    3, 35, 11, 43, 1, 33, 9, 41, 51, 19, 59, 27, 49, 17, 57, 25,
    15, 47, 7, 39, 13, 45, 5, 37, 63, 31, 55, 23, 61, 29, 53, 21,
)

#: The final pass on a calibrated display (psyop.rendering.scene.OutputTransfer): normalised luminance -> the
#: fractional code (binary search in the forward table, linear between its entries) -> an integer code (ordered
#: dither or rounding), written as code / 255 so any 8-bit conversion of the float image gives that code exactly.
OUTPUT_FRAGMENT_SHADER = """
#version 410 core
#define ROW %(row)d
uniform sampler2D u_linear;   // the ray-cast's image, normalised luminance
uniform sampler2D u_table;    // the forward table, row-major in rows of ROW texels: l at code 255 k / (n - 1)
uniform int u_table_size;     // n
uniform int u_dither;         // 1: ordered dither, 0: round
uniform float u_offset;       // this frame's threshold offset: frac(frame * golden ratio)
const int BAYER[64] = int[64](%(bayer)s);
out vec4 frag_colour;

float entry(int k, int channel) { return texelFetch(u_table, ivec2(k %% ROW, k / ROW), 0)[channel]; }

float code_of(float l, int channel) {
    if (!(l > entry(0, channel))) return 0.0;
    if (l >= entry(u_table_size - 1, channel)) return 255.0;
    int lo = 0; int hi = u_table_size - 1;  // entry(lo) < l <= entry(hi)
    while (hi - lo > 1) {
        int mid = (lo + hi) / 2;
        if (entry(mid, channel) < l) lo = mid; else hi = mid;
    }
    float a = entry(lo, channel); float b = entry(hi, channel);
    return (float(lo) + (l - a) / (b - a)) * 255.0 / float(u_table_size - 1);
}

void main() {
    ivec2 fc = ivec2(gl_FragCoord.xy);
    vec4 lin = texelFetch(u_linear, fc, 0);
    vec3 code = vec3(code_of(lin.r, 0), code_of(lin.g, 1), code_of(lin.b, 2));
    float t = fract((float(BAYER[(fc.y & 7) * 8 + (fc.x & 7)]) + 0.5) / 64.0 + u_offset);
    vec3 q = (u_dither == 1) ? floor(code + t) : floor(code + 0.5);
    vec3 nearest = floor(code + 0.5);
    q = mix(q, nearest, vec3(lessThan(abs(code - nearest), vec3(1e-3))));
    frag_colour = vec4(clamp(q, 0.0, 255.0) / 255.0, lin.a);
}
""" % {"bayer": ", ".join(str(b) for b in BAYER_8X8), "row": OUTPUT_TABLE_ROW}
