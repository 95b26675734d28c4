"""Build psyop's glTF 2.0 assets (assets/README.md) from procedural geometry and generated textures.

Run ``python assets/build_assets.py [OUT_DIR]`` (default: this folder). Everything is seeded
and written with trimesh's glTF exporter, a different tool from psyop's loader (pygltflib,
psyop.mesh.load), so what psyop reads comes from another writer. tests/mesh/test_assets.py
rebuilds the files and checks they are byte-identical to the committed ones.

Units are metres; axes are glTF's (+y up, a model's front faces +z, the viewer looks along -z).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

tf = trimesh.transformations
HERE = Path(__file__).resolve().parent

# ---- textures (generated here: CC0) ---------------------------------------------------------


def wood_planks(size_px: int = 256, planks: int = 4, seed: int = 1) -> Image.Image:
    """Floor boards: ``planks`` boards across, each its own tint, with a fine grain."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size_px, 0:size_px] / size_px
    board = np.minimum((x * planks).astype(int), planks - 1)
    tint = rng.uniform(0.8, 1.15, planks)[board]
    grain = 0.08 * np.sin(2 * np.pi * (y * 9 + 0.35 * np.sin(2 * np.pi * x * 3 + board))) \
        + 0.04 * rng.standard_normal((size_px, size_px))
    seam = (np.abs((x * planks) - np.round(x * planks)) * size_px / planks) < 1.0
    base = np.array([0.55, 0.36, 0.2])
    rgb = np.clip(base[None, None, :] * (tint + grain)[..., None], 0, 1)
    rgb[seam] *= 0.45
    return Image.fromarray(np.round(rgb * 255).astype(np.uint8), "RGB")


def wallpaper(size_px: int = 256, stripes: int = 8, seed: int = 2) -> Image.Image:
    """Wallpaper: soft vertical stripes with a small repeating dot pattern and paper noise."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size_px, 0:size_px] / size_px
    stripe = 0.5 + 0.5 * np.cos(2 * np.pi * x * stripes)
    dots = (np.hypot((x * stripes * 2) % 1 - 0.5, (y * stripes * 2) % 1 - 0.5) < 0.12).astype(float)
    paper = 0.03 * rng.standard_normal((size_px, size_px))
    light = np.array([0.86, 0.82, 0.7])
    dark = np.array([0.7, 0.62, 0.5])
    rgb = light * (1 - 0.35 * stripe[..., None]) + dark * 0.35 * stripe[..., None]
    rgb = rgb * (1 - 0.18 * dots[..., None]) + paper[..., None]
    return Image.fromarray(np.round(np.clip(rgb, 0, 1) * 255).astype(np.uint8), "RGB")


def label(size_px: int = 128, seed: int = 3) -> Image.Image:
    """A bottle label: a cream band with dark lines of 'text' (a feature the teaser's occluder hides)."""
    rng = np.random.default_rng(seed)
    rgb = np.ones((size_px, size_px, 3)) * np.array([0.93, 0.88, 0.72])
    for row in range(20, size_px - 20, 14):
        for start in range(10, size_px - 10, 22):
            width = int(rng.integers(8, 18))
            rgb[row:row + 5, start:start + width] = [0.35, 0.1, 0.08]
    rgb[:6], rgb[-6:] = [0.6, 0.45, 0.1], [0.6, 0.45, 0.1]
    return Image.fromarray(np.round(rgb * 255).astype(np.uint8), "RGB")


# ---- geometry -------------------------------------------------------------------------------


def colour(rgba: tuple[float, float, float, float], *, alpha_mode: str | None = None,
           double_sided: bool = False) -> trimesh.visual.TextureVisuals:
    """An untextured material with a linear base-colour factor."""
    factor = np.round(np.asarray(rgba) * 255).astype(np.uint8)
    material = trimesh.visual.material.PBRMaterial(baseColorFactor=factor, metallicFactor=0.0, roughnessFactor=1.0,
                                                   alphaMode=alpha_mode, doubleSided=double_sided)
    return trimesh.visual.TextureVisuals(material=material)


def textured_quad(width_m: float, height_m: float, image: Image.Image, tile_m: float) -> trimesh.Trimesh:
    """A quad in the z = 0 plane facing +z, centred, its texture repeating every ``tile_m``."""
    hw, hh = width_m / 2, height_m / 2
    vertices = np.array([[-hw, -hh, 0], [hw, -hh, 0], [hw, hh, 0], [-hw, hh, 0]])
    uv = np.array([[0, 0], [width_m, 0], [width_m, height_m], [0, height_m]]) / tile_m
    material = trimesh.visual.material.PBRMaterial(baseColorTexture=image, metallicFactor=0.0, roughnessFactor=1.0)
    return trimesh.Trimesh(vertices, [[0, 1, 2], [0, 2, 3]], process=False,
                           visual=trimesh.visual.TextureVisuals(uv=uv, material=material))


def box(extents: tuple[float, float, float], centre: tuple[float, float, float], rgba: tuple[float, ...]) -> trimesh.Trimesh:
    mesh = trimesh.creation.box(extents, transform=tf.translation_matrix(centre))
    mesh.visual = colour(rgba)  # type: ignore[arg-type]
    return mesh


def upright_cylinder(radius_m: float, height_m: float, base_y: float, sections: int) -> trimesh.Trimesh:
    """A cylinder standing on y = base_y (trimesh's cylinders run along z)."""
    mesh = trimesh.creation.cylinder(radius=radius_m, height=height_m, sections=sections)
    mesh.apply_transform(tf.rotation_matrix(-np.pi / 2, [1, 0, 0]))
    mesh.apply_translation([0, base_y + height_m / 2, 0])
    return mesh


def bottle_meshes(sections: int = 96) -> dict[str, trimesh.Trimesh]:
    """A wine bottle standing on y = 0: body, shoulder and neck revolved, and a textured label band."""
    profile = np.array([[0.0, 0.0], [0.036, 0.0], [0.037, 0.004], [0.037, 0.2], [0.033, 0.225], [0.02, 0.25],
                        [0.0135, 0.265], [0.0135, 0.32], [0.0145, 0.322], [0.0145, 0.33], [0.0, 0.33]])
    glass = trimesh.creation.revolve(profile, sections=sections)  # revolves about z: y of the profile is z
    glass.apply_transform(tf.rotation_matrix(-np.pi / 2, [1, 0, 0]))
    glass.visual = colour((0.04, 0.16, 0.06, 1.0))  # type: ignore[arg-type]
    # the label: an open cylinder band just outside the glass, u around, v up
    angles = np.linspace(0, 2 * np.pi, sections + 1)
    ring = np.column_stack([np.sin(angles), np.cos(angles)]) * 0.0375
    lower = np.column_stack([ring[:, 0], np.full(sections + 1, 0.07), ring[:, 1]])
    upper = np.column_stack([ring[:, 0], np.full(sections + 1, 0.16), ring[:, 1]])
    vertices = np.vstack([lower, upper])
    k = np.arange(sections)
    n = sections + 1
    faces = np.vstack([np.column_stack([k, k + 1, n + k + 1]), np.column_stack([k, n + k + 1, n + k])])
    uv = np.vstack([np.column_stack([angles / (2 * np.pi) * 2, np.zeros(n)]),
                    np.column_stack([angles / (2 * np.pi) * 2, np.ones(n)])])
    material = trimesh.visual.material.PBRMaterial(baseColorTexture=label(), metallicFactor=0.0, roughnessFactor=1.0)
    band = trimesh.Trimesh(vertices, faces, process=False, visual=trimesh.visual.TextureVisuals(uv=uv, material=material))
    return {"bottle_glass": glass, "bottle_label": band}


def candle_meshes(sections: int = 64) -> dict[str, trimesh.Trimesh]:
    """A dinner candle in a holder standing on y = 0, with a wick and a translucent (BLEND) flame."""
    holder = upright_cylinder(0.03, 0.012, 0.0, sections)
    holder.visual = colour((0.55, 0.45, 0.2, 1.0))  # type: ignore[arg-type]
    wax = upright_cylinder(0.011, 0.2, 0.012, sections)
    wax.visual = colour((0.9, 0.88, 0.8, 1.0))  # type: ignore[arg-type]
    wick = upright_cylinder(0.0012, 0.01, 0.212, 8)
    wick.visual = colour((0.05, 0.05, 0.05, 1.0))  # type: ignore[arg-type]
    flame = trimesh.creation.icosphere(subdivisions=2, radius=0.006)
    flame.apply_scale([1.0, 2.4, 1.0])
    flame.apply_translation([0, 0.232, 0])
    flame.visual = colour((1.0, 0.62, 0.12, 0.7), alpha_mode="BLEND")  # type: ignore[arg-type]
    return {"candle_holder": holder, "candle_wax": wax, "candle_wick": wick, "candle_flame": flame}


def revolved_along_x(profile: list[list[float]], sections: int) -> trimesh.Trimesh:
    """A solid of revolution of (radius, distance) ``profile`` points about +x, from x = 0."""
    mesh = trimesh.creation.revolve(np.asarray(profile, dtype=float), sections=sections)
    mesh.apply_transform(tf.rotation_matrix(np.pi / 2, [0, 1, 0]))
    return mesh


def revolved_upright(profile: list[list[float]], sections: int) -> trimesh.Trimesh:
    """A solid of revolution of (radius, height) ``profile`` points about +y, from y = 0."""
    mesh = trimesh.creation.revolve(np.asarray(profile, dtype=float), sections=sections)
    mesh.apply_transform(tf.rotation_matrix(-np.pi / 2, [1, 0, 0]))
    return mesh


def plate_mesh() -> trimesh.Trimesh:
    """A dinner plate 0.26 m across with a raised rim, standing on y = 0."""
    profile = [[0, 0.004], [0.08, 0.004], [0.085, 0.0], [0.09, 0.0], [0.1, 0.006], [0.125, 0.016], [0.13, 0.018],
               [0.13, 0.02], [0.124, 0.019], [0.098, 0.01], [0.08, 0.008], [0, 0.008]]
    plate = revolved_upright(profile, 96)
    plate.visual = colour((0.9, 0.9, 0.92, 1.0))  # type: ignore[arg-type]
    return plate


def wine_glass_mesh() -> trimesh.Trimesh:
    """A wine glass 0.2 m high (drawn opaque-tinted: BLEND, alpha 0.35), standing on y = 0."""
    profile = [[0, 0], [0.035, 0], [0.035, 0.003], [0.006, 0.006], [0.004, 0.012], [0.004, 0.09], [0.02, 0.1],
               [0.038, 0.125], [0.042, 0.15], [0.038, 0.2], [0.036, 0.2], [0.039, 0.15], [0.035, 0.127],
               [0.018, 0.104], [0, 0.1]]
    glass = revolved_upright(profile, 64)
    glass.visual = colour((0.8, 0.85, 0.9, 0.35), alpha_mode="BLEND")  # type: ignore[arg-type]
    return glass


def pencil_meshes() -> dict[str, trimesh.Trimesh]:
    """A hexagonal pencil 0.19 m long along x, centred on the origin, point towards +x."""
    radius, body, cone, eraser, ferrule = 0.0037, 0.150, 0.022, 0.01, 0.008
    x0 = -0.095
    hexagon = trimesh.creation.cylinder(radius=radius, height=body, sections=6)
    hexagon.apply_transform(tf.rotation_matrix(np.pi / 2, [0, 1, 0]))
    hexagon.apply_translation([x0 + eraser + ferrule + body / 2, 0, 0])
    hexagon.visual = colour((0.95, 0.62, 0.02, 1.0))  # type: ignore[arg-type]
    # the sharpened wood is a truncated cone; the last 6 mm of the point are graphite
    lead_m = 0.006
    tip_radius = radius * lead_m / cone
    wood = revolved_along_x([[0, 0], [radius, 0], [tip_radius, cone - lead_m], [0, cone - lead_m]], 24)
    wood.apply_translation([x0 + eraser + ferrule + body, 0, 0])
    wood.visual = colour((0.85, 0.68, 0.45, 1.0))  # type: ignore[arg-type]
    lead = revolved_along_x([[0, 0], [tip_radius, 0], [0, lead_m]], 24)
    lead.apply_translation([0.095 - lead_m, 0, 0])
    lead.visual = colour((0.08, 0.08, 0.09, 1.0))  # type: ignore[arg-type]
    metal = trimesh.creation.cylinder(radius=radius * 1.05, height=ferrule, sections=24)
    metal.apply_transform(tf.rotation_matrix(np.pi / 2, [0, 1, 0]))
    metal.apply_translation([x0 + eraser + ferrule / 2, 0, 0])
    metal.visual = colour((0.6, 0.6, 0.62, 1.0))  # type: ignore[arg-type]
    rubber = trimesh.creation.cylinder(radius=radius * 0.98, height=eraser, sections=24)
    rubber.apply_transform(tf.rotation_matrix(np.pi / 2, [0, 1, 0]))
    rubber.apply_translation([x0 + eraser / 2, 0, 0])
    rubber.visual = colour((0.85, 0.35, 0.4, 1.0))  # type: ignore[arg-type]
    return {"pencil_body": hexagon, "pencil_wood": wood, "pencil_lead": lead, "pencil_ferrule": metal,
            "pencil_eraser": rubber}


def chair(x: float, z: float, facing: float) -> dict[str, trimesh.Trimesh]:
    """A chair (seat 0.45 m high, back 0.9 m) with its own pieces, turned ``facing`` rad about y."""
    wood = (0.32, 0.18, 0.08, 1.0)
    parts = {"seat": box((0.44, 0.04, 0.42), (0, 0.45, 0), wood),
             "back": box((0.44, 0.42, 0.03), (0, 0.69, -0.195), wood)}
    for i, (lx, lz) in enumerate([(-0.19, -0.18), (0.19, -0.18), (-0.19, 0.18), (0.19, 0.18)]):
        parts[f"leg{i}"] = box((0.04, 0.43, 0.04), (lx, 0.215, lz), wood)
    place = tf.concatenate_matrices(tf.translation_matrix([x, 0, z]), tf.rotation_matrix(facing, [0, 1, 0]))
    for mesh in parts.values():
        mesh.apply_transform(place)
    return parts


def dining_room() -> trimesh.Scene:
    """The egocentric study's room: origin on the floor below the seated viewer's eyes, viewer facing -z.

    4 m wide (x -2..2), 5 m deep (z 0.5..-4.5), 2.6 m high; a 1.4 x 0.9 m table (top at 0.75 m)
    1.6 m ahead, four chairs (two at its far side, one at each end), three plates, two wine glasses
    (BLEND), a candle (its flame BLEND) and a bottle with a textured label on it.
    """
    scene = trimesh.Scene()
    width, depth, height, z_front, z_back = 4.0, 5.0, 2.6, 0.5, -4.5
    zc = (z_front + z_back) / 2
    paper = wallpaper()
    floor = textured_quad(width, depth, wood_planks(), tile_m=1.0)
    floor.apply_transform(tf.concatenate_matrices(tf.translation_matrix([0, 0, zc]),
                                                  tf.rotation_matrix(-np.pi / 2, [1, 0, 0])))
    scene.add_geometry(floor, node_name="floor", geom_name="floor")
    walls = {"back_wall": (width, tf.translation_matrix([0, height / 2, z_back])),
             "front_wall": (width, tf.concatenate_matrices(tf.translation_matrix([0, height / 2, z_front]),
                                                           tf.rotation_matrix(np.pi, [0, 1, 0]))),
             "left_wall": (depth, tf.concatenate_matrices(tf.translation_matrix([-width / 2, height / 2, zc]),
                                                          tf.rotation_matrix(np.pi / 2, [0, 1, 0]))),
             "right_wall": (depth, tf.concatenate_matrices(tf.translation_matrix([width / 2, height / 2, zc]),
                                                           tf.rotation_matrix(-np.pi / 2, [0, 1, 0])))}
    for name, (span, place) in walls.items():  # each faces into the room
        wall = textured_quad(span, height, paper, tile_m=0.5)
        wall.apply_transform(place)
        scene.add_geometry(wall, node_name=name, geom_name=name)
    ceiling = box((width, 0.02, depth), (0, height + 0.01, zc), (0.92, 0.92, 0.9, 1.0))
    scene.add_geometry(ceiling, node_name="ceiling", geom_name="ceiling")
    table_z, top = -1.6, 0.75
    table = {"table_top": box((1.4, 0.04, 0.9), (0, top - 0.02, table_z), (0.4, 0.24, 0.12, 1.0))}
    for i, (lx, lz) in enumerate([(-0.63, -0.38), (0.63, -0.38), (-0.63, 0.38), (0.63, 0.38)]):
        table[f"table_leg{i}"] = box((0.06, top - 0.04, 0.06), (lx, (top - 0.04) / 2, table_z + lz), (0.3, 0.17, 0.08, 1.0))
    for name, mesh in table.items():
        scene.add_geometry(mesh, node_name=name, geom_name=name)
    for c, (x, z, facing) in enumerate([(-0.35, table_z - 0.65, 0.0), (0.35, table_z - 0.65, 0.0),
                                        (-0.95, table_z, np.pi / 2), (0.95, table_z, -np.pi / 2)]):
        for part, mesh in chair(x, z, facing).items():
            scene.add_geometry(mesh, node_name=f"chair{c}_{part}", geom_name=f"chair{c}_{part}")
    for p, (x, z) in enumerate([(-0.4, table_z + 0.2), (0.0, table_z - 0.25), (0.42, table_z + 0.15)]):
        plate = plate_mesh()
        plate.apply_translation([x, top, z])
        scene.add_geometry(plate, node_name=f"plate{p}", geom_name=f"plate{p}")
    for g, (x, z) in enumerate([(-0.25, table_z + 0.33), (0.58, table_z + 0.3)]):
        glass = wine_glass_mesh()
        glass.apply_translation([x, top, z])
        scene.add_geometry(glass, node_name=f"wine_glass{g}", geom_name=f"wine_glass{g}")
    for name, mesh in candle_meshes().items():
        mesh.apply_translation([-0.12, top, table_z + 0.05])
        scene.add_geometry(mesh, node_name=name, geom_name=name)
    for name, mesh in bottle_meshes().items():
        mesh.apply_translation([0.2, top, table_z - 0.15])
        scene.add_geometry(mesh, node_name=name, geom_name=name)
    return scene


def grouped(groups: dict[str, dict[str, trimesh.Trimesh]], offsets: dict[str, list[float]]) -> trimesh.Scene:
    """A scene with one parent node per group (placed at its offset) and the group's meshes under it."""
    scene = trimesh.Scene()
    for group, meshes in groups.items():
        scene.graph.update(frame_to=group, frame_from=scene.graph.base_frame,
                           matrix=tf.translation_matrix(offsets.get(group, [0, 0, 0])))
        for name, mesh in meshes.items():
            scene.add_geometry(mesh, node_name=name, geom_name=name, parent_node_name=group)
    return scene


def teaser() -> trimesh.Scene:
    """Fig. 1's arrangement: a candle (node ``candle``) 0.25 m in front of a bottle (node ``bottle``),
    both standing on y = 0 on the line of sight along -z, the candle at the origin."""
    return grouped({"candle": candle_meshes(), "bottle": bottle_meshes()}, {"bottle": [0.0, 0.0, -0.25]})


def pencil() -> trimesh.Scene:
    """The reach target: one ``pencil`` node, 0.19 m along x, centred."""
    return grouped({"pencil": pencil_meshes()}, {})


ASSETS = {"dining_room.glb": dining_room, "pencil.glb": pencil, "teaser.glb": teaser}


def build(out_dir: Path) -> list[Path]:
    """Write every asset into ``out_dir``; returns their paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for name, make in ASSETS.items():
        data = trimesh.exchange.gltf.export_glb(make(), include_normals=False)
        (out_dir / name).write_bytes(data)
        written.append(out_dir / name)
    return written


if __name__ == "__main__":
    for path in build(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE):
        print(f"{path}: {path.stat().st_size} bytes")
