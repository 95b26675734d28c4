"""Protocol texts shared by tests that need a small two-interval study around their own scene."""

from __future__ import annotations

#: phases, design and response of a minimal 2IFC study: ocular test vs conventional reference,
#: level_D 0 and 1, one repetition (append it to a header and a ``scene:`` list)
TWO_INTERVAL_TAIL = """trial:
  phases:
    - {kind: interval, duration_s: 1}
    - {kind: interval, duration_s: 1}
    - {kind: response, expected_s: 1}
design:
  factors:
    level_D: {levels: [0, 1]}
  repetitions: 1
  randomisation: {kind: full}
response:
  kind: two_interval
  test: {mode: ocular}
  reference: {mode: conventional}
  level_factor: level_D
  order: balanced
"""


def disc_on_wall_head(study: str) -> str:
    """A stereo protocol's head (``study``'s name, the display with the ipd from the tracker, the scene): a red
    8 deg disc at 1 D in front of a blue 60 deg wall at 0.5 D; append a tail such as :data:`TWO_INTERVAL_TAIL`."""
    return f"""
psyop_protocol: 1
study: {{name: {study}, title: a red disc in front of a blue wall seen by both eyes}}
display: {{profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: tracker}}
eyes: stereo
scene:
  - id: target
    kind: disc
    size_deg: 8
    depth: {{D: 1}}
    surface: {{kind: solid, rgb: [1, 0, 0]}}
  - id: wall
    kind: quad
    width_deg: 60
    height_deg: 60
    depth: {{D: 0.5}}
    surface: {{kind: solid, rgb: [0.2, 0.2, 0.6]}}
"""


#: protocols/egocentric.yaml's mesh dining room, and the analytic box room it replaced (kind: room, the
#: same size), for tests of the room primitive: ``text.replace(EGOCENTRIC_MESH_ROOM, EGOCENTRIC_BOX_ROOM)``
EGOCENTRIC_MESH_ROOM = """  - id: room
    kind: mesh
    file: ../assets/dining_room.glb
    position_m: [0, -1.2, 0]            # assumed: the floor 1.2 m below the eyes (seated)
"""
#: protocols/egocentric.yaml's reach target object, a mesh pencil (it replaced ``object: pencil``, the analytic one)
EGOCENTRIC_MESH_PENCIL = """    object:                             # Sec. 6.2: the reach target is a pencil; assumed: this mesh (hexagonal,
      file: ../assets/pencil.glb        # yellow, assets/README.md), lying across the view, point to the right
      node: pencil
"""
EGOCENTRIC_BOX_ROOM = """  - id: room
    kind: room
    width_m: 4
    depth_m: 5
    height_m: 2.6
    table_height_m: 0.75
    eye_height_m: 1.2
"""
