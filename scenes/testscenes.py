"""Parametric test scenes (bpy-free, numpy only) for tests, benchmarks and the demo.

Conventions (same as :mod:`relight_addon.core.scene`):

* lengths in metres, z is up (Blender convention);
* every patch is a planar quad ``(a, b, c, d)`` counter-clockwise seen from its front, the
  front normal is ``normalize((c - a) x (d - b))``;
* ``emission`` is exitance in W/m^2 (radiosity units), emitted from the front only
  (Lambertian, so the radiance is ``emission / pi``);
* ``rho`` is linear-RGB diffuse albedo; a patch only receives and reflects on its front side,
  its back side is black (it absorbs everything that reaches it).

Functions
---------
``cornell_box(subdivide=1, ...)``       closed Cornell box with a non-occluding ceiling lamp
``closed_cube(rho, emission, n=1)``     furnace: inward-facing unit cube, uniform rho and E
``parallel_squares(distance=1, ...)``   unit emitter above a unit receiver, optional blocker
``perpendicular_squares()``             unit emitter and unit receiver sharing an edge
``ceiling_fixture()``                   a fluorescent tube between two reflectors, over a floor

Analytic form factors for the two-square scenes are in ``PARALLEL_UNIT_SQUARES_F1`` and
``PERPENDICULAR_UNIT_SQUARES_F``.
"""
from __future__ import annotations

import numpy as np

from relight_addon.core.scene import SceneData, quads_from_boxes

# Area-averaged form factor between parallel, directly opposed unit squares at distance 1.
PARALLEL_UNIT_SQUARES_F1 = 0.199825
# Form factor between two perpendicular unit squares that share an edge.
PERPENDICULAR_UNIT_SQUARES_F = 0.200044

WHITE = (0.75, 0.75, 0.75)
RED = (0.63, 0.065, 0.05)
GREEN = (0.14, 0.45, 0.09)

# Group ids of cornell_box() (one per object).
CORNELL_GROUPS = {
    "floor": 0, "ceiling": 1, "back_wall": 2, "front_wall": 3,
    "left_wall_red": 4, "right_wall_green": 5, "short_box": 6, "tall_box": 7, "lamp": 8,
}


# -- helpers ------------------------------------------------------------------------------
def subdivide_quads(corners, n: int) -> np.ndarray:
    """Split each planar quad (q, 4, 3) into n x n quads (q * n * n, 4, 3), keeping the
    orientation.  Sub-quads of quad i are consecutive (row-major in the bilinear (u, v))."""
    corners = np.asarray(corners, float).reshape(-1, 4, 3)
    n = int(n)
    if n < 1:
        raise ValueError("n must be >= 1")
    if n == 1:
        return corners.copy()
    t = np.linspace(0.0, 1.0, n + 1)
    u0, v0 = np.meshgrid(t[:-1], t[:-1], indexing="xy")
    u1, v1 = u0 + 1.0 / n, v0 + 1.0 / n
    # corners of the sub-quads in (u, v): (u0,v0) (u1,v0) (u1,v1) (u0,v1) keeps CCW order
    uv = np.stack([np.stack([u0, v0], -1), np.stack([u1, v0], -1),
                   np.stack([u1, v1], -1), np.stack([u0, v1], -1)], axis=-2).reshape(-1, 4, 2)
    u = uv[None, :, :, 0, None]
    v = uv[None, :, :, 1, None]
    a, b, c, d = (corners[:, None, None, i, :] for i in range(4))
    pts = (1 - u) * (1 - v) * a + u * (1 - v) * b + u * v * c + (1 - u) * v * d
    return pts.reshape(-1, 4, 3)


def flip(corners) -> np.ndarray:
    """Reverse the orientation of quads (a, b, c, d) -> (a, d, c, b)."""
    corners = np.asarray(corners, float)
    return corners[..., [0, 3, 2, 1], :].copy()


def _rotate_z(points, center, degrees):
    th = np.radians(degrees)
    c, s = np.cos(th), np.sin(th)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    center = np.asarray(center, float)
    return (np.asarray(points, float) - center) @ rot.T + center


def _square(z, facing_up: bool, x0=0.0, y0=0.0, size=1.0):
    a = [x0, y0, z]
    b = [x0 + size, y0, z]
    c = [x0 + size, y0 + size, z]
    d = [x0, y0 + size, z]
    q = np.array([[a, b, c, d]], float)
    return q if facing_up else flip(q)


def _assemble(parts, lamp_names=()):
    """parts: list of (corners (q,4,3), rho, emission, lamp, occluder, group)."""
    cs, rhos, ems, lamps, occ, groups = [], [], [], [], [], []
    for corners, rho, emission, lamp, occluder, group in parts:
        q = len(corners)
        cs.append(corners)
        rhos.append(np.broadcast_to(np.asarray(rho, float), (q, 3)))
        ems.append(np.broadcast_to(np.asarray(emission, float), (q, 3)))
        lamps.append(np.full(q, lamp, np.int32))
        occ.append(np.full(q, occluder, bool))
        groups.append(np.full(q, group, np.int32))
    return SceneData(corners=np.concatenate(cs), rho=np.concatenate(rhos),
                     emission=np.concatenate(ems), lamp=np.concatenate(lamps),
                     lamp_names=list(lamp_names), occluder=np.concatenate(occ),
                     group=np.concatenate(groups))


# -- scenes -------------------------------------------------------------------------------
def cornell_box(subdivide: int = 1, lamp_exitance=(50.0, 50.0, 50.0), lamp_occluder: bool = False,
                front_wall: bool = True, size: float = 5.5, lamp_gap: float = 0.01) -> SceneData:
    """Cornell box (simplified, axis-aligned version of the published Cornell geometry, scaled
    from 556 mm to ``size`` metres; default 5.5 m), z up.

    Room ``[0, size]^3``: floor z=0, ceiling z=size, back wall y=size, front wall y=0 (closes
    the box so the room is watertight; ``front_wall=False`` gives the classic open box),
    red wall x=0 (left seen from the front), green wall x=size.  All room normals point into the
    room.  Two white boxes stand on the floor (outward normals, no bottom face since it lies on
    the floor): the short box (0.3 size cube, centred at (0.663, 0.307) size, rotated +17 deg
    about z) and the tall box (0.3 x 0.3 x 0.6 size, centred at (0.330, 0.638) size, rotated
    -17 deg).

    The lamp is a ``0.236 size x 0.191 size`` rectangle (1.3 m x 1.05 m at size 5.5, like the
    published 130 mm x 105 mm light) centred under the ceiling at ``z = size - lamp_gap``,
    facing down, exitance ``lamp_exitance`` (W/m^2, default 50 per channel), rho 0, lamp index
    0 ("ceiling lamp").  By default it is NOT an occluder (like a Blender area light: it emits
    but does not block or reflect); ``lamp_occluder=True`` makes it a black occluding panel.

    Every surface quad is split into ``subdivide x subdivide`` patches (the lamp too).
    Reflectances: white (0.75, 0.75, 0.75), red (0.63, 0.065, 0.05), green (0.14, 0.45, 0.09).
    Group ids per object: see ``CORNELL_GROUPS``.  Patch order: floor, ceiling, back, front,
    red, green, short box (top, front, back, left, right), tall box (same), lamp.
    """
    s = float(size)
    n = int(subdivide)
    g = CORNELL_GROUPS
    room = flip(quads_from_boxes([s / 2, s / 2, s / 2], [s, s, s]))  # inward normals
    bottom, top, front, back, left, right = room
    parts = [
        (subdivide_quads(bottom, n), WHITE, 0.0, -1, True, g["floor"]),
        (subdivide_quads(top, n), WHITE, 0.0, -1, True, g["ceiling"]),
        (subdivide_quads(back, n), WHITE, 0.0, -1, True, g["back_wall"]),
    ]
    if front_wall:
        parts.append((subdivide_quads(front, n), WHITE, 0.0, -1, True, g["front_wall"]))
    parts += [
        (subdivide_quads(left, n), RED, 0.0, -1, True, g["left_wall_red"]),
        (subdivide_quads(right, n), GREEN, 0.0, -1, True, g["right_wall_green"]),
    ]
    boxes = [("short_box", (0.663, 0.307), 0.3, +17.0), ("tall_box", (0.330, 0.638), 0.6, -17.0)]
    for name, (cx, cy), height, angle in boxes:
        center = np.array([cx * s, cy * s, height * s / 2])
        faces = quads_from_boxes(center, [0.3 * s, 0.3 * s, height * s])[1:]  # drop the bottom
        faces = _rotate_z(faces, center, angle)
        parts.append((subdivide_quads(faces, n), WHITE, 0.0, -1, True, g[name]))
    lx, ly = 0.236 * s, 0.191 * s
    x0, x1, y0, y1, z = (s - lx) / 2, (s + lx) / 2, (s - ly) / 2, (s + ly) / 2, s - lamp_gap
    lamp = flip(np.array([[[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]]]))  # facing down
    parts.append((subdivide_quads(lamp, n), 0.0, lamp_exitance, 0, bool(lamp_occluder), g["lamp"]))
    return _assemble(parts, lamp_names=["ceiling lamp"])


def closed_cube(rho=0.5, emission=1.0, n: int = 1) -> SceneData:
    """Furnace test: the unit cube ``[0, 1]^3`` with its six faces facing INWARD, each split into
    n x n quads; uniform ``rho`` and uniform ``emission`` (exitance, W/m^2) on every patch, all
    patches are lamp 0 ("cube") and occluders.  Exact solution: B = E / (1 - rho) everywhere and
    the incident irradiance H = B (every patch sees only the enclosure).  Group = face index
    (0 bottom, 1 top, 2 front -y, 3 back +y, 4 left -x, 5 right +x)."""
    faces = flip(quads_from_boxes([0.5, 0.5, 0.5], [1.0, 1.0, 1.0]))
    parts = [(subdivide_quads(faces[i], n), rho, emission, 0, True, i) for i in range(6)]
    return _assemble(parts, lamp_names=["cube"])


def clutter_furnace(rho=0.9, touching=False) -> SceneData:
    """A closed 1 m room in which every face emits 1 and reflects ``rho``, holding two 2 cm
    cubes 1 mm apart and two thin 20 x 20 cm panels 1 mm apart (issue 10): the exact radiosity
    is 1 / (1 - rho) on every face that can be seen.  ``touching``: a 10 cm box standing on the
    floor too (its bottom face lies on the floor).  The room's 6 faces come first."""
    parts = [flip(quads_from_boxes([0.5, 0.5, 0.5], [1, 1, 1])),
             quads_from_boxes([0.40, 0.5, 0.3], [0.02, 0.02, 0.02]),
             quads_from_boxes([0.421, 0.5, 0.3], [0.02, 0.02, 0.02]),
             quads_from_boxes([0.6, 0.5, 0.3], [0.2, 0.002, 0.2]),
             quads_from_boxes([0.6, 0.503, 0.3], [0.2, 0.002, 0.2])]
    if touching:
        parts.append(quads_from_boxes([0.3, 0.3, 0.01], [0.1, 0.1, 0.02]))
    return SceneData(np.concatenate(parts), rho, 1.0, 0, ["all"])


def hover_furnace(rho=0.9) -> SceneData:
    """The closed 1 m furnace of clutter_furnace (every face emits 1 and reflects ``rho``:
    1 / (1 - rho) everywhere) holding what hovers just off a face (issue 47): pairs of boxes of
    1, 2, 5 and 10 cm, 1 mm above the floor and 1 mm apart; three thin panels 1 mm apart; a
    5 cm box 1 mm off a wall.  The room's 6 faces come first."""
    parts = [flip(quads_from_boxes([0.5, 0.5, 0.5], [1, 1, 1]))]
    x = 0.1
    for size in (0.01, 0.02, 0.05, 0.1):
        for _ in range(2):
            parts.append(quads_from_boxes([x + size / 2, 0.3, 0.001 + size / 2], [size] * 3))
            x += size + 0.001
        x += 0.05
    for k in range(3):
        parts.append(quads_from_boxes([0.5, 0.7 + 0.003 * k, 0.4], [0.3, 0.002, 0.3]))
    parts.append(quads_from_boxes([0.974, 0.5, 0.6], [0.05, 0.05, 0.05]))
    return SceneData(np.concatenate(parts), rho, 1.0, 0, ["all"])


def blinds_room(slats=6, gap=0.01) -> SceneData:
    """A closed 1 m room (rho 0.7) lit by a square lamp under its ceiling, with venetian blinds
    in the middle: ``slats`` single quads 40 cm square, ``gap`` apart, slightly tilted, each
    two-sided as orient makes it (core/relight/orient.py: a back copy, reversed, that blocks no
    ray).  Patch order: the room's 6 faces, the slats, their backs, the lamp."""
    room = flip(quads_from_boxes([0.5, 0.5, 0.5], [1, 1, 1]))
    fronts = np.array([[[0.3, 0.3, z], [0.7, 0.3, z], [0.7, 0.7, z + 0.008], [0.3, 0.7, z + 0.008]]
                       for z in 0.4 + gap * np.arange(slats)])
    lamp = np.array([[[0.4, 0.4, 0.99], [0.4, 0.6, 0.99], [0.6, 0.6, 0.99], [0.6, 0.4, 0.99]]])
    corners = np.concatenate([room, fronts, fronts[:, ::-1], lamp])
    p = len(corners)
    rho = np.full((p, 3), 0.7)
    rho[-1] = 0.0
    emission = np.zeros((p, 3))
    emission[-1] = 10.0
    lamp_of = np.full(p, -1)
    lamp_of[-1] = 0
    occluder = np.ones(p, bool)
    occluder[len(room) + slats:len(room) + 2 * slats] = False
    return SceneData(corners, rho, emission, lamp_of, ["lamp"], occluder=occluder)


def parallel_squares(distance: float = 1.0, blocker: bool = False, blocker_size: float = 0.5,
                     receiver_rho=0.5, emitter_exitance=1.0) -> SceneData:
    """Unit emitter square ``[0,1]^2`` at ``z = distance`` facing DOWN (exitance
    ``emitter_exitance``, rho 0, lamp 0, occluder) above a unit receiver square at z = 0 facing
    UP (rho ``receiver_rho``).  With ``blocker=True`` a black (rho 0) square of side
    ``blocker_size`` centred at (0.5, 0.5, distance / 2) is added as ONE occluding patch facing
    down (towards the emitter); visibility is side-independent so it blocks both ways.

    Patch order: 0 emitter, 1 receiver, 2 blocker.  Groups: 0 emitter, 1 receiver, 2 blocker.
    Direct (emitter-only) irradiance on the receiver for distance 1 without blocker:
    ``emitter_exitance * PARALLEL_UNIT_SQUARES_F1`` (= F_receiver->emitter)."""
    parts = [
        (_square(distance, facing_up=False), 0.0, emitter_exitance, 0, True, 0),
        (_square(0.0, facing_up=True), receiver_rho, 0.0, -1, True, 1),
    ]
    if blocker:
        h = blocker_size
        parts.append((_square(distance / 2, facing_up=False, x0=0.5 - h / 2, y0=0.5 - h / 2, size=h),
                      0.0, 0.0, -1, True, 2))
    return _assemble(parts, lamp_names=["emitter"])


def perpendicular_squares(receiver_rho=0.5, emitter_exitance=1.0) -> SceneData:
    """Two unit squares sharing the edge x = 0, z = 0 (y in [0, 1]): the receiver lies in z = 0
    (x in [0, 1]) facing UP, the emitter in x = 0 (z in [0, 1]) facing +x (exitance
    ``emitter_exitance``, rho 0, lamp 0).  Patch order: 0 emitter, 1 receiver.
    Direct irradiance on the receiver = ``emitter_exitance * PERPENDICULAR_UNIT_SQUARES_F``."""
    emitter = np.array([[[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]]], float)  # normal +x
    parts = [
        (emitter, 0.0, emitter_exitance, 0, True, 0),
        (_square(0.0, facing_up=True), receiver_rho, 0.0, -1, True, 1),
    ]
    return _assemble(parts, lamp_names=["emitter"])


def ceiling_fixture() -> SceneData:
    """One of the 24 tube fixtures of RenderPark's classroom (etc/salon/classroom.mgf), its
    coordinates relative to the tube, 3.46 m over a 20 m square floor (rho 0.5) that makes the
    total area the classroom's (403 m^2: the presets' element sizes are fractions of it).
    The fixture is a 1.4 m trough, rho 0.8: two slanted reflectors 10 cm wide facing each
    other and down, end caps, a top; its tube (1.3 m x 4 cm, exitance 556 / 553 / 504, rho
    0.5) faces down between the reflectors, 2 cm under the top.  Patch order: 0-4 the
    trough's outside (left, cap, right, cap, top), 5 the left reflector, 6 a cap, 7 the right
    reflector, 8 a cap, 9 the top inside, 10 the tube (lamp 0), 11 the floor."""
    trough = np.array([
        [[-0.04, 0.7, 0.02], [-0.1, 0.7, -0.06], [-0.1, -0.7, -0.06], [-0.04, -0.7, 0.02]],
        [[-0.04, 0.7, 0.02], [0.04, 0.7, 0.02], [0.1, 0.7, -0.06], [-0.1, 0.7, -0.06]],
        [[0.1, 0.7, -0.06], [0.04, 0.7, 0.02], [0.04, -0.7, 0.02], [0.1, -0.7, -0.06]],
        [[0.1, -0.7, -0.06], [0.04, -0.7, 0.02], [-0.04, -0.7, 0.02], [-0.1, -0.7, -0.06]],
        [[0.04, 0.7, 0.02], [-0.04, 0.7, 0.02], [-0.04, -0.7, 0.02], [0.04, -0.7, 0.02]],
        [[-0.098, 0.698, -0.062], [-0.038, 0.698, 0.018], [-0.038, -0.698, 0.018],
         [-0.098, -0.698, -0.062]],
        [[-0.038, 0.698, 0.018], [-0.098, 0.698, -0.062], [0.098, 0.698, -0.062],
         [0.038, 0.698, 0.018]],
        [[0.038, 0.698, 0.018], [0.098, 0.698, -0.062], [0.098, -0.698, -0.062],
         [0.038, -0.698, 0.018]],
        [[-0.098, -0.698, -0.062], [-0.038, -0.698, 0.018], [0.038, -0.698, 0.018],
         [0.098, -0.698, -0.062]],
        [[-0.038, 0.698, 0.018], [0.038, 0.698, 0.018], [0.038, -0.698, 0.018],
         [-0.038, -0.698, 0.018]]], float)
    tube = np.array([[[-0.02, -0.65, 0.0], [-0.02, 0.65, 0.0], [0.02, 0.65, 0.0],
                      [0.02, -0.65, 0.0]]])
    side = 20.0
    floor = np.array([[[-side / 2, -side / 2, -3.46], [side / 2, -side / 2, -3.46],
                       [side / 2, side / 2, -3.46], [-side / 2, side / 2, -3.46]]])
    return _assemble([(trough, 0.8, 0.0, -1, True, 0),
                      (tube, 0.5, (556.5, 552.7, 504.1), 0, True, 1),
                      (floor, 0.5, 0.0, -1, True, 2)], lamp_names=["tube"])
