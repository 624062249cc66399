"""A family of seeded test rooms (the relighting's held-out-able benchmark) and their Cycles bakes.

The office of :mod:`scenes.office` is one room; the relighting was tuned on it.  This module
makes rooms that vary what real rooms vary: size and aspect (3-8 m, ceiling 2.4-3.5 m), 1-4
lamps of unequal powers (ratios up to 4:1) and colours (warm / neutral / cool white, tinted),
lamp types (area RECTANGLE / SQUARE / DISK / ELLIPSE, POINT with a radius, SPOT, SUN through a
window hole, emissive meshes), ceiling and wall-mounted lamps 0.2-1.5 m from the nearest wall,
albedo from dark (0.1) to white (0.85), plain and patterned textures (checker, stripes, noise,
wood), posters (separate quads or painted into a wall texture), furniture (tables, shelves,
boxes, cabinets) and texel densities 128-512 per wall (24-32 in the small test rooms; room 19
has one 512-texel wall, its other surfaces at 128: ``_Room.shell(..., texels={surface: n})``).

Two halves, like the office:

* bpy-free: ``room_spec(index) -> RoomSpec`` (deterministic from the index), ``FAMILY``,
  ``TEST_ROOMS``, ``HELD_OUT``, ``coverage(surface)``, ``spec_hash(spec)``, ``load_bakes(index)``.
* bpy: ``build_room(spec, orientation="visible")`` creates the room in the current
  (factory-empty) scene; ``benchmarks/family_bakes.py`` builds and bakes every room.

Conventions (as :mod:`scenes.office`): metres, z up; a surface is one object made of planar
quads ``(n, 4, 3)`` whose corners are counter-clockwise around the VISIBLE normal (the side
that is photographed), UVs ``(n, 4, 2)`` (axis-aligned rectangles in [0, 1]^2, never sharing a
texel), the true albedo is linear RGB float32 ``(H, W, 3)``, row 0 at v = 0 (Blender's pixel
order).  The room is x in [0, W], y in [0, D], z in [0, H]; walls "Wall South" (y = 0),
"Wall North" (y = D), "Wall West" (x = 0), "Wall East" (x = W).

Lamps: ``Lamp.power`` is the Blender value that the bakes switch: ``Light.energy`` for lights
(W, Normalize on for area lights; W/m^2 irradiance for the SUN) and the Emission ``Strength``
for emissive meshes.  Measured here (Blender 5.0.1): an Emission strength S gives the outgoing
radiance S, i.e. an exitance of pi * S W/m^2 per emitting side (a 1 m^2 panel at S = 100 lights
a white plane 1 m below 3.1x as much as a 100 W, 1 m^2 area light), so ``Lamp.power_w`` =
pi * S * area for an emissive mesh.  ``Lamp.weight`` is the lamp's relative strength in its
room (1-4): power = the type's base power x weight, so weight ratios are the "unequal power"
ratios of the issue, comparable across lamp types (bases: area 55 W, point 140 W, spot 260 W,
emissive 55 W per side).  The sun is the exception: its strength is 3.5 W/m^2 x weight and
what enters depends on the window: room 3's sun (weight 1, ~4 W through a 1.7 m^2 window) is a
faint patch next to an 82 W lamp, rooms 9 and 13 (weights 8 and 5) have bright sun patches.

Faces the other way (room 18, "from another program"): in ``build_room(spec, "file")`` the
quads with ``Surface.flipped`` are built reversed (room shell normals pointing outward, some
furniture faces flipped), as an imported model would be; the thin single-plane panels (a table
top and a partition, lit from both sides) are single quads.  Cycles' DIFFUSE bake shades the
side the face normal points to: a face whose normal points away from the light bakes exactly 0
(tested in tests/test_family_data.py::test_cycles_bakes_the_normal_side), even though a render
shows it lit (Cycles shades back faces two-sided) and it still casts shadows from both sides.
So the truth is baked from ``build_room(spec, "visible")`` (every quad towards its visible
side); the "file" orientation is what the add-on is given.  A single-plane panel's texture
holds its visible side only; the light on its other side is in no texture.

Bakes (``benchmarks/family_bakes.py``, cached in ``benchmarks/family/bakes/room_NN/`` and, for
the small TEST_ROOMS, ``tests/data/family/room_NN/``): per room one Cycles DIFFUSE bake
(direct + indirect + colour, 16 bounces, no adaptive sampling, no clamping) per lamp alone at
its power with seed 1 (the truth basis; truth(I) = sum_k I_k bake_k by linearity) and one with
all lamps on, seed 0 (the "photo").  See ``load_bakes`` and ``benchmarks/family/README.md``.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field

import numpy as np

from scenes.office import _atlas_uvs, _box_faces, _quad, _smooth_noise

GENERATOR_VERSION = "family-v1"
SEEDED = list(range(16))            # generated rooms 0-15
BUG_A, BUG_B, OTHER_PROGRAM = 16, 17, 18
DENSE_WALL = 19                     # one wall at 512 texels, the rest at 128
TEST_ROOMS = [20, 21, 22]           # small rooms (32 texels) for pytest, bakes in tests/data
FAMILY = SEEDED + [BUG_A, BUG_B, OTHER_PROGRAM, DENSE_WALL] + TEST_ROOMS
HELD_OUT = [12, 13, 14, 15]         # never used for tuning
LETTERS = "ABCDEFGH"

# Relative lamp strengths: power = BASE[type] * weight.
BASE_POWER = {"AREA": 55.0, "POINT": 140.0, "SPOT": 260.0, "SUN": 3.5, "MESH": 55.0}
COLOURS = {
    "neutral white": (1.0, 1.0, 1.0),
    "warm white": (1.0, 0.80, 0.58),
    "cool white": (0.80, 0.90, 1.0),
    "amber": (1.0, 0.66, 0.35),
    "pink tint": (1.0, 0.72, 0.82),
    "green tint": (0.78, 1.0, 0.74),
    "blue tint": (0.62, 0.76, 1.0),
    "sunlight": (1.0, 0.93, 0.82),
}

_REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BAKE_DIR = os.path.join(_REPO, "benchmarks", "family", "bakes")
TEST_BAKE_DIR = os.path.join(_REPO, "tests", "data", "family")


# -- data ----------------------------------------------------------------------------------------

@dataclass
class Surface:
    """One surface object: quads (n, 4, 3), uvs (n, 4, 2), albedo (H, W, 3) float32."""
    name: str
    kind: str                      # floor ceiling wall furniture poster panel
    quads: np.ndarray
    uvs: np.ndarray
    albedo: np.ndarray
    pattern: str = "plain"
    flipped: np.ndarray | None = None   # (n,) bool: reversed in the "file" orientation

    @property
    def normals(self) -> np.ndarray:
        q = self.quads
        n = np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 1])
        return n / np.linalg.norm(n, axis=1, keepdims=True)


@dataclass
class Lamp:
    name: str
    type: str                      # AREA POINT SPOT SUN MESH
    power: float                   # Blender value switched by the bakes (see module doc)
    colour: tuple
    colour_name: str
    weight: float                  # relative strength in the room (1..4)
    location: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))  # columns: local x, y, z
    mount: str = "ceiling"         # ceiling wall floor table outside
    shape: str = ""                # AREA: RECTANGLE SQUARE DISK ELLIPSE
    size: float = 0.0
    size_y: float = 0.0
    radius: float = 0.0            # POINT / SPOT shadow_soft_size
    spot_size: float = 0.0         # full cone angle (rad)
    spot_blend: float = 0.0
    angle: float = 0.0             # SUN angular diameter (rad)
    quads: np.ndarray | None = None  # MESH: (n, 4, 3), counter-clockwise around the emitting side
    two_sided: bool = False        # MESH: emits from both sides (lampshade)
    wall_distance: float = float("nan")  # horizontal distance to the nearest wall (m)

    @property
    def direction(self) -> np.ndarray:
        """Emitting direction (-local z) of AREA / SPOT / SUN lamps."""
        return -self.rotation[:, 2]

    @property
    def power_w(self) -> float:
        """Watts (per emitting side for meshes, W/m^2 for the sun)."""
        if self.type == "MESH":
            q = self.quads
            area = 0.5 * np.linalg.norm(np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 1]), axis=1).sum()
            return float(np.pi * self.power * area)
        return float(self.power)

    def summary(self) -> str:
        kind = {"AREA": f"area {self.shape.lower()}", "POINT": f"point r={self.radius:.2f}",
                "SPOT": f"spot {np.degrees(self.spot_size):.0f}deg/{self.spot_blend:.2f}",
                "SUN": "sun through window", "MESH": "emissive mesh"}[self.type]
        p = (f"{self.power:.2f} W/m2" if self.type == "SUN" else
             f"S={self.power:.1f} ({self.power_w:.0f} W)" if self.type == "MESH" else f"{self.power:.0f} W")
        d = "" if self.type == "SUN" else f", {self.wall_distance:.2f} m from wall"
        return f"{self.name}: {kind}, {self.mount}, {p}, {self.colour_name}{d}"


@dataclass
class RoomSpec:
    index: int
    description: str
    size: tuple                    # (W, D, H) metres
    texel: int                     # texture size of the walls (of every shell surface not in texels)
    surfaces: list
    lamps: list
    camera_location: tuple
    camera_target: tuple
    held_out: bool = False
    window: dict | None = None     # {"wall": name, "uv": (u0, u1, v0, v1)} hole in that wall
    pilot: bool = False            # a low-resolution copy (sample-count pilot)
    texels: dict = field(default_factory=dict)  # {shell surface: size} where it is not ``texel``

    @property
    def name(self) -> str:
        return f"room_{self.index:02d}"

    def surface(self, name) -> Surface:
        return next(s for s in self.surfaces if s.name == name)

    def lamp(self, name) -> Lamp:
        return next(lp for lp in self.lamps if lp.name == name)

    @property
    def lamp_powers(self) -> dict:
        return {lp.name: lp.power for lp in self.lamps}

    @property
    def objects(self) -> list:
        return [s.name for s in self.surfaces]


# -- albedo patterns -----------------------------------------------------------------------------

def _palette(rng, level):
    """Two colours for a pattern at an albedo level: 'dark' 0.1-0.3, 'mid' 0.25-0.7,
    'light' 0.55-0.8, 'white' 0.7-0.85."""
    lo, hi = {"dark": (0.1, 0.3), "mid": (0.25, 0.7), "light": (0.55, 0.8),
              "white": (0.7, 0.85)}[level]
    base = rng.uniform(lo, hi)
    a = np.clip(base * rng.uniform(0.8, 1.2, 3), lo, hi)
    b = np.clip(rng.uniform(lo, hi) * rng.uniform(0.8, 1.2, 3), lo, hi)
    return a, b, lo, hi


def albedo_pattern(kind, rng, h, w=None, level="mid", periods=4):
    """(h, w, 3) linear albedo: plain, checker, stripes, hstripes, noise, wood."""
    w = h if w is None else w
    a, b, lo, hi = _palette(rng, level)
    v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    if kind == "plain":
        t = np.zeros((h, w))
    elif kind == "checker":
        t = ((np.floor(u * periods) + np.floor(v * periods)) % 2).astype(float)
    elif kind == "stripes":
        t = (np.floor(u * periods * 2) % 2).astype(float)
    elif kind == "hstripes":
        t = (np.floor(v * periods) % 2).astype(float)
    elif kind == "noise":
        t = _smooth_noise(rng, h, w, cells=5)
    elif kind == "wood":
        # planks along u, rings from a distorted distance, grain noise
        plank = np.floor(v * periods)
        off = rng.uniform(0, 10, periods + 1)[plank.astype(int)]
        d = 14.0 * (u + off) + 2.5 * _smooth_noise(rng, h, w, cells=3)
        t = 0.5 + 0.5 * np.sin(2 * np.pi * d)
        t = 0.7 * t + 0.3 * (plank % 2)
        a = np.array([0.55, 0.36, 0.2]) * (hi / 0.7)
        b = np.array([0.36, 0.22, 0.11]) * (hi / 0.7)
        a, b = np.clip(a, 0.1, 0.85), np.clip(b, 0.1, 0.85)
    else:
        raise ValueError(kind)
    img = a[None, None] * (1 - t[..., None]) + b[None, None] * t[..., None]
    return np.clip(img, 0.1, 0.85).astype(np.float32)


def _paint_poster(rng, img, u0, u1, v0, v1):
    """A poster painted into a wall texture: a light frame and colour blocks."""
    h, w = img.shape[:2]
    r0, r1, c0, c1 = int(v0 * h), int(v1 * h), int(u0 * w), int(u1 * w)
    img[r0:r1, c0:c1] = 0.8
    fr = max(1, (r1 - r0) // 12)
    inner = img[r0 + fr:r1 - fr, c0 + fr:c1 - fr]
    hh, ww = inner.shape[:2]
    for _ in range(4):
        col = rng.uniform(0.08, 0.8, 3)
        a, b = sorted(rng.integers(0, hh + 1, 2))
        c, d = sorted(rng.integers(0, ww + 1, 2))
        inner[a:b, c:d] = col
    return img


def _poster_image(rng, n):
    img = np.full((n, n, 3), 0.8, np.float32)
    return _paint_poster(rng, img, 0.0, 1.0, 0.0, 1.0).astype(np.float32)


# -- geometry helpers ----------------------------------------------------------------------------

def _frame(direction, up=(0.0, 0.0, 1.0)):
    """Rotation (columns x, y, z) whose -z is ``direction``."""
    z = -np.asarray(direction, float)
    z /= np.linalg.norm(z)
    up = np.asarray(up, float)
    if abs(np.dot(up, z)) > 0.99:
        up = np.array([0.0, 1.0, 0.0]) if abs(z[1]) < 0.99 else np.array([1.0, 0.0, 0.0])
    x = np.cross(up, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.column_stack([x, y, z])


def _wall_quads(o, du, dv, hole=None):
    """A wall o + u du + v dv, (u, v) in [0, 1]^2, with an optional hole (u0, u1, v0, v1):
    quads and their UVs (the hole's texels are left unused)."""
    rects = [(0, 1, 0, 1)] if hole is None else [
        (0, 1, 0, hole[2]), (0, 1, hole[3], 1), (0, hole[0], hole[2], hole[3]),
        (hole[1], 1, hole[2], hole[3])]
    o, du, dv = (np.asarray(x, float) for x in (o, du, dv))
    quads, uvs = [], []
    for u0, u1, v0, v1 in rects:
        c = [(u0, v0), (u1, v0), (u1, v1), (u0, v1)]
        quads.append([o + u * du + v * dv for u, v in c])
        uvs.append(c)
    return np.array(quads), np.array(uvs, float)


def _shell(W, D, H):
    """Floor, ceiling and walls as (name, kind, origin, du, dv) with inward normals."""
    return [("Floor", "floor", (0, 0, 0), (W, 0, 0), (0, D, 0)),
            ("Ceiling", "ceiling", (0, D, H), (W, 0, 0), (0, -D, 0)),
            ("Wall South", "wall", (W, 0, 0), (-W, 0, 0), (0, 0, H)),
            ("Wall North", "wall", (0, D, 0), (W, 0, 0), (0, 0, H)),
            ("Wall West", "wall", (0, 0, 0), (0, D, 0), (0, 0, H)),
            ("Wall East", "wall", (W, D, 0), (0, -D, 0), (0, 0, H))]


def _wall_point(W, D, wall, along, height, out=0.0):
    """Point on a wall at ``along`` metres from its left end (seen from inside), ``out`` metres
    into the room; also the inward normal."""
    if wall == "Wall South":
        return np.array([W - along, out, height]), np.array([0.0, 1, 0])
    if wall == "Wall North":
        return np.array([along, D - out, height]), np.array([0.0, -1, 0])
    if wall == "Wall West":
        return np.array([out, along, height]), np.array([1.0, 0, 0])
    return np.array([W - out, D - along, height]), np.array([-1.0, 0, 0])


def _wall_length(W, D, wall):
    return W if wall in ("Wall South", "Wall North") else D


def _furniture_boxes(kind, lo, hi):
    """Box list (lo, hi, skip) of a piece of furniture in the footprint lo..hi (x, y) of height
    hi[2]."""
    (x0, y0, _), (x1, y1, z1) = lo, hi
    out = []
    if kind == "table":
        t = 0.05
        out.append(((x0, y0, z1 - t), (x1, y1, z1), ()))
        leg = 0.06
        for lx, ly in ((x0 + 0.04, y0 + 0.04), (x1 - 0.04 - leg, y0 + 0.04),
                       (x0 + 0.04, y1 - 0.04 - leg), (x1 - 0.04 - leg, y1 - 0.04 - leg)):
            out.append(((lx, ly, 0.0), (lx + leg, ly + leg, z1 - t), ("-z", "+z")))
    elif kind == "shelf":
        t = 0.03
        out.append(((x0, y0, 0.0), (x0 + t, y1, z1), ("-z",)))
        out.append(((x1 - t, y0, 0.0), (x1, y1, z1), ("-z",)))
        n = 4
        for i in range(n):
            z = 0.08 + i * (z1 - 0.08) / n
            out.append(((x0 + t, y0, z), (x1 - t, y1, z + t), ("-x", "+x")))
        out.append(((x0 + t, y0, z1 - t), (x1 - t, y1, z1), ("-x", "+x")))
    else:  # box, cabinet
        out.append(((x0, y0, 0.0), (x1, y1, z1), ("-z",)))
    return out


def _rotate_xy(quads, centre, k):
    """Rotate quads by k * 90 degrees about the vertical axis through centre."""
    c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][k % 4]
    q = np.array(quads, float)
    x, y = q[..., 0] - centre[0], q[..., 1] - centre[1]
    q[..., 0], q[..., 1] = centre[0] + c * x - s * y, centre[1] + s * x + c * y
    return q


# -- the room builder (numpy) ------------------------------------------------------------------

class _Room:
    """Accumulates surfaces and lamps of one room."""

    def __init__(self, index, size, texel, rng, level="mid", furn_texel=None):
        self.index, self.size, self.texel, self.rng = index, tuple(map(float, size)), int(texel), rng
        self.level = level
        self.furn_texel = int(furn_texel or max(24, texel // 2))
        self.texels = {}               # per-surface texture sizes that differ from ``texel``
        self.surfaces, self.lamps, self.footprints = [], [], []
        self.window = None
        self.posters = 0

    def texel_of(self, name):
        """Texture size (square) of the shell surface ``name``: its override or ``texel``."""
        return int(self.texels.get(name, self.texel))

    # shell
    def shell(self, patterns, hole=None, poster=None, texels=None):
        """patterns: {name: (kind, level, periods)}; hole: (wall, (u0, u1, v0, v1));
        poster: (wall, (u0, u1, v0, v1)) painted into that wall's texture; texels: {name: n}
        per-surface texture sizes (n x n) instead of the room's ``texel`` (e.g. one dense wall)."""
        W, D, H = self.size
        names = {nm for nm, *_ in _shell(W, D, H)}
        unknown = set(texels or {}) - names
        if unknown:
            raise KeyError(f"no shell surface {sorted(unknown)}; surfaces: {sorted(names)}")
        self.texels.update({k: int(v) for k, v in (texels or {}).items() if int(v) != self.texel})
        for name, kind, o, du, dv in _shell(W, D, H):
            pk, lvl, per = patterns.get(name, ("plain", self.level, 4))
            h = self.texel_of(name)
            img = albedo_pattern(pk, self.rng, h, h, lvl, per)
            wall_hole = hole[1] if hole is not None and hole[0] == name else None
            quads, uvs = _wall_quads(o, du, dv, wall_hole)
            if poster is not None and poster[0] == name:
                _paint_poster(self.rng, img, *poster[1])
            self.surfaces.append(Surface(name, kind, quads, uvs, img, pk))
        if hole is not None:
            self.window = {"wall": hole[0], "uv": tuple(float(x) for x in hole[1])}

    def free(self, lo, hi, margin=0.1):
        for a, b in self.footprints:
            if lo[0] < b[0] + margin and a[0] < hi[0] + margin and lo[1] < b[1] + margin and a[1] < hi[1] + margin:
                return False
        return True

    def furniture(self, name, kind, lo, hi, pattern="noise", level=None, rotate=0, texel=None):
        lo, hi = np.asarray(lo, float), np.asarray(hi, float)
        boxes = _furniture_boxes(kind, lo, hi)
        faces = []
        for blo, bhi, skip in boxes:
            faces += _box_faces(blo, bhi, skip)
        faces = np.array(faces)
        if rotate:
            faces = _rotate_xy(faces, 0.5 * (lo[:2] + hi[:2]), rotate)
        n = int(texel or self.furn_texel)
        uvs = _atlas_uvs(len(faces), n)
        img = albedo_pattern(pattern, self.rng, n, n, level or self.level, 3)
        self.surfaces.append(Surface(name, "furniture", faces, uvs, img, pattern))
        fl, fh = faces[..., :2].reshape(-1, 2).min(0), faces[..., :2].reshape(-1, 2).max(0)
        self.footprints.append((fl, fh))
        return self.surfaces[-1]

    def place(self, name, kind, sx, sy, sz, pattern="noise", level=None, against=None,
              region=None, texel=None, tries=200):
        """Place furniture at random: against a wall (back 2 cm from it) or free-standing."""
        W, D, _ = self.size
        rng = self.rng
        for _ in range(tries):
            if against is not None:
                L = _wall_length(W, D, against)
                a = rng.uniform(0.3, max(0.31, L - sx - 0.3))
                if against == "Wall South":
                    lo, hi = (W - a - sx, 0.02), (W - a, 0.02 + sy)
                elif against == "Wall North":
                    lo, hi = (a, D - 0.02 - sy), (a + sx, D - 0.02)
                elif against == "Wall West":
                    lo, hi = (0.02, a), (0.02 + sy, a + sx)
                else:
                    lo, hi = (W - 0.02 - sy, D - a - sx), (W - 0.02, D - a)
            else:
                x0, x1, y0, y1 = region or (0.4, W - 0.4, 0.4, D - 0.4)
                x = rng.uniform(x0, max(x0 + 0.01, x1 - sx))
                y = rng.uniform(y0, max(y0 + 0.01, y1 - sy))
                lo, hi = (x, y), (x + sx, y + sy)
            if self.free(lo, hi):
                return self.furniture(name, kind, (*lo, 0.0), (*hi, sz), pattern, level, texel=texel)
        raise RuntimeError(f"room {self.index}: no room for {name}")

    def poster_quad(self, wall, along, bottom, w, h, texel=None):
        """A poster as a separate thin quad 1 cm in front of a wall."""
        W, D, _ = self.size
        p0, n = _wall_point(W, D, wall, along, bottom, out=0.01)
        p1, _ = _wall_point(W, D, wall, along + w, bottom, out=0.01)
        du = p1 - p0
        q = _quad(p0, du, (0, 0, h))
        self.posters += 1
        n_tex = int(texel or max(24, self.texel // 2))
        s = Surface(f"Poster {self.posters}", "poster", q[None], np.array(
            [[[0, 0], [1, 0], [1, 1], [0, 1]]], float) * (1 - 2 / n_tex) + 1 / n_tex,
            _poster_image(self.rng, n_tex), "poster")
        self.surfaces.append(s)

    # lamps
    def _name(self):
        return f"Lamp {LETTERS[len(self.lamps)]}"

    def _add(self, lamp):
        W, D, _ = self.size
        if lamp.type == "MESH":
            pts = lamp.quads.reshape(-1, 3)
            d = min(pts[:, 0].min(), W - pts[:, 0].max(), pts[:, 1].min(), D - pts[:, 1].max())
        elif lamp.type == "SUN":
            d = float("nan")
        else:
            x, y = lamp.location[:2]
            d = min(x, W - x, y, D - y)
        lamp.wall_distance = float(d)
        self.lamps.append(lamp)
        return lamp

    def area(self, shape, centre, direction, sx, sy, weight, colour, mount, up=(0, 0, 1)):
        return self._add(Lamp(self._name(), "AREA", BASE_POWER["AREA"] * weight, COLOURS[colour],
                              colour, weight, np.asarray(centre, float), _frame(direction, up),
                              mount, shape, sx, sy if shape in ("RECTANGLE", "ELLIPSE") else sx))

    def ceiling_area(self, shape, xy, sx, sy, weight, colour, gap=0.02):
        H = self.size[2]
        return self.area(shape, (xy[0], xy[1], H - gap), (0, 0, -1), sx, sy, weight, colour,
                         "ceiling", up=(0, 1, 0))

    def wall_area(self, shape, wall, along, height, out, sx, sy, weight, colour, tilt=0.6):
        """A wall-mounted lamp ``out`` metres from the wall, facing into the room and down."""
        W, D, _ = self.size
        p, n = _wall_point(W, D, wall, along, height, out)
        d = n * np.cos(tilt) - np.array([0, 0, 1.0]) * np.sin(tilt)
        return self.area(shape, p, d, sx, sy, weight, colour, "wall")

    def point(self, location, radius, weight, colour, mount="ceiling"):
        return self._add(Lamp(self._name(), "POINT", BASE_POWER["POINT"] * weight, COLOURS[colour],
                              colour, weight, np.asarray(location, float), np.eye(3), mount,
                              radius=radius))

    def spot(self, location, target, size_deg, blend, radius, weight, colour, mount="ceiling"):
        loc = np.asarray(location, float)
        return self._add(Lamp(self._name(), "SPOT", BASE_POWER["SPOT"] * weight, COLOURS[colour],
                              colour, weight, loc, _frame(np.asarray(target, float) - loc), mount,
                              radius=radius, spot_size=np.radians(size_deg), spot_blend=blend))

    def sun(self, direction, strength_weight, colour="sunlight", angle_deg=0.53):
        return self._add(Lamp(self._name(), "SUN", BASE_POWER["SUN"] * strength_weight,
                              COLOURS[colour], colour, strength_weight,
                              np.array([0.0, 0.0, 10.0]), _frame(direction), "outside",
                              angle=np.radians(angle_deg)))

    def mesh_panel(self, centre, sx, sy, weight, colour, label="Panel", direction=(0, 0, -1)):
        """A glowing one-sided rectangle facing ``direction`` (e.g. a ceiling panel 1 cm down)."""
        R = _frame(direction, up=(0, 1, 0) if abs(direction[2]) > 0.9 else (0, 0, 1))
        x, y = R[:, 0] * sx / 2, R[:, 1] * sy / 2
        c = np.asarray(centre, float)
        # counter-clockwise around the emitting normal (-local z)
        q = np.array([[c - x - y, c - x + y, c + x + y, c + x - y]])
        area = sx * sy
        strength = BASE_POWER["MESH"] * weight / (np.pi * area)
        return self._add(Lamp(f"{self._name()} {label}", "MESH", strength, COLOURS[colour], colour,
                              weight, c, R, "ceiling" if direction[2] < -0.9 else "wall",
                              quads=q, size=sx, size_y=sy))

    def lampshade(self, base_xy, z0, z1, r0, r1, weight, colour, n=8, label="Shade", mount="floor"):
        """A glowing open frustum (a lampshade of n quads, both sides emit) from z0 to z1."""
        a = np.linspace(0, 2 * np.pi, n + 1)
        cx, cy = base_xy
        q = []
        for i in range(n):
            p = [(cx + r0 * np.cos(a[i]), cy + r0 * np.sin(a[i]), z0),
                 (cx + r0 * np.cos(a[i + 1]), cy + r0 * np.sin(a[i + 1]), z0),
                 (cx + r1 * np.cos(a[i + 1]), cy + r1 * np.sin(a[i + 1]), z1),
                 (cx + r1 * np.cos(a[i]), cy + r1 * np.sin(a[i]), z1)]
            q.append(p)          # normal outward
        q = np.array(q)
        area = 0.5 * np.linalg.norm(np.cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 1]), axis=1).sum()
        strength = BASE_POWER["MESH"] * weight / (np.pi * area)
        return self._add(Lamp(f"{self._name()} {label}", "MESH", strength, COLOURS[colour], colour,
                              weight, np.array([cx, cy, 0.5 * (z0 + z1)]), np.eye(3), mount,
                              quads=q, two_sided=True, size=2 * r1, size_y=z1 - z0))

    def spec(self, description, camera=None, held_out=False):
        W, D, H = self.size
        cam = camera or ((W - 0.3, 0.3, min(1.7, H - 0.5)), (0.35 * W, 0.7 * D, 0.35 * H))
        return RoomSpec(self.index, description, self.size, self.texel, self.surfaces, self.lamps,
                        tuple(map(float, cam[0])), tuple(map(float, cam[1])), held_out, self.window,
                        texels=dict(self.texels))


# -- the rooms ------------------------------------------------------------------------------------

_WALLS = ("Wall South", "Wall North", "Wall West", "Wall East")


def _weights(rng, n, ratio):
    """n unequal relative strengths in [1, ratio] (max / min = ratio exactly when n >= 2)."""
    if n == 1:
        return [1.0]
    w = np.r_[1.0, ratio, rng.uniform(1.0, ratio, n - 2)]
    rng.shuffle(w)
    return [float(x) for x in w]


def _room_patterns(rng, level, kinds):
    """Per-surface (pattern, level, periods) from a list of pattern kinds cycled over the shell."""
    names = ["Floor", "Ceiling", *_WALLS]
    out = {}
    for i, nm in enumerate(names):
        k = kinds[i % len(kinds)]
        lvl = level
        if nm == "Ceiling":
            k, lvl = "plain" if rng.random() < 0.6 else "noise", ("white" if level != "dark" else "mid")
        out[nm] = (k, lvl, int(rng.integers(3, 7)))
    return out


def _seeded(index, texel=None):
    """Rooms 0-15: a theme per index (so every variation of the issue is present), details from
    the seed."""
    rng = np.random.default_rng(1000 + index)
    T = texel
    # theme: size, height, texel, level, patterns, lamps(callable), furniture list
    if index == 0:
        r = _Room(0, (5.0, 4.0, 2.7), T or 128, rng, "mid")
        r.shell(_room_patterns(rng, "mid", ["wood", "stripes", "noise", "plain"]),
                poster=("Wall North", (0.3, 0.55, 0.4, 0.8)))
        r.place("Table", "table", 1.4, 0.8, 0.74, "wood")
        r.place("Box 1", "box", 0.5, 0.4, 0.45, "checker", against="Wall East")
        w = _weights(rng, 2, 1.5)
        r.ceiling_area("RECTANGLE", (1.4, 1.6), 1.2, 0.6, w[0], "warm white")
        r.ceiling_area("RECTANGLE", (3.6, 2.1), 1.2, 0.6, w[1], "neutral white")
        return r.spec("office-like: two ceiling panels, warm and neutral, table and box")
    if index == 1:
        r = _Room(1, (8.0, 3.0, 2.6), T or 128, rng, "mid")
        r.shell(_room_patterns(rng, "mid", ["wood", "stripes", "hstripes", "noise"]))
        r.place("Shelf 1", "shelf", 1.2, 0.35, 1.8, "wood", against="Wall North")
        r.place("Shelf 2", "shelf", 0.9, 0.35, 1.5, "plain", against="Wall North")
        r.place("Box 1", "box", 0.6, 0.5, 0.5, "checker")
        w = _weights(rng, 3, 3.0)
        for i, x in enumerate((1.4, 4.0, 6.7)):
            r.ceiling_area("DISK", (x, 1.5 + rng.uniform(-0.2, 0.2)), 0.5, 0.5, w[i], "cool white")
        return r.spec("long corridor-like room, three cool ceiling disks 1:3, shelves",
                      camera=((7.7, 0.4, 1.6), (1.0, 2.2, 0.9)))
    if index == 2:
        r = _Room(2, (3.0, 3.2, 2.4), T or 256, rng, "dark", furn_texel=(T or 256) // 4)
        r.shell(_room_patterns(rng, "dark", ["noise", "plain", "checker"]))
        r.place("Table", "table", 0.9, 0.6, 0.72, "wood", "dark")
        r.point((1.5, 1.7, 1.95), 0.1, 1.0, "warm white", mount="pendant")
        return r.spec("small dark room (albedo 0.1-0.3), one warm pendant point lamp, 256 texels",
                      camera=((2.8, 0.2, 1.6), (0.8, 2.6, 0.6)))
    if index == 3:
        r = _Room(3, (4.5, 4.0, 2.8), T or 128, rng, "white")
        r.shell(_room_patterns(rng, "white", ["wood", "plain", "plain", "noise"]),
                hole=("Wall South", (0.35, 0.65, 0.32, 0.78)))
        r.place("Table", "table", 1.2, 0.8, 0.74, "plain", "mid", region=(0.8, 3.5, 0.8, 2.6))
        r.place("Cabinet", "cabinet", 0.8, 0.45, 1.1, "plain", "mid", against="Wall North")
        r.sun((-0.25, 0.75, -0.6), 1.0)
        r.wall_area("SQUARE", "Wall West", 2.0, 2.0, 0.2, 0.3, 0.3, 1.5, "cool white")
        return r.spec("white room: sun through a south window, cool wall lamp 0.2 m from wall",
                      camera=((4.2, 3.7, 1.6), (1.5, 0.5, 0.6)))
    if index == 4:
        r = _Room(4, (6.0, 5.0, 3.0), T or 128, rng, "mid")
        r.shell(_room_patterns(rng, "mid", ["checker", "plain", "noise", "hstripes"]))
        r.poster_quad("Wall North", 1.0, 1.2, 0.7, 1.0)
        r.poster_quad("Wall North", 3.6, 1.0, 0.6, 0.9)
        r.place("Table", "table", 1.6, 0.9, 0.75, "wood", region=(1.5, 4.5, 1.2, 3.2))
        w = _weights(rng, 2, 2.5)
        r.mesh_panel((1.5, 2.5, 2.99), 0.6, 0.6, w[0], "neutral white")
        r.spot((4.5, 1.5, 2.9), (3.9, 5.0, 1.5), 40, 0.3, 0.05, w[1], "warm white")
        return r.spec("emissive ceiling panel and a warm spot on the poster wall",
                      camera=((5.7, 0.3, 1.7), (2.0, 4.5, 1.0)))
    if index == 5:
        r = _Room(5, (7.0, 6.0, 3.2), T or 128, rng, "mid")
        r.shell(_room_patterns(rng, "mid", ["wood", "noise", "stripes", "plain"]),
                poster=("Wall East", (0.55, 0.75, 0.35, 0.65)))
        r.place("Table 1", "table", 1.8, 0.9, 0.74, "wood")
        r.place("Cabinet 1", "cabinet", 1.0, 0.5, 1.9, "plain", against="Wall North")
        r.place("Box 1", "box", 0.5, 0.5, 0.5, "checker")
        w = _weights(rng, 4, 4.0)
        r.ceiling_area("RECTANGLE", (1.3, 3.0), 1.0, 0.5, w[0], "neutral white")
        r.ceiling_area("RECTANGLE", (5.0, 4.5), 1.0, 0.5, w[1], "pink tint")
        r.wall_area("ELLIPSE", "Wall South", 1.5, 2.1, 0.3, 0.5, 0.3, w[2], "amber")
        r.point((5.5, 1.2, 2.5), 0.15, w[3], "green tint")
        return r.spec("large room, four tinted lamps 1:4 (2 rect, wall ellipse, point), cabinet",
                      camera=((6.7, 0.3, 1.8), (2.0, 5.0, 0.8)))
    if index == 6:
        r = _Room(6, (5.0, 5.0, 3.5), T or 128, rng, "mid")
        r.shell(_room_patterns(rng, "mid", ["wood", "noise", "plain", "checker"]))
        r.place("Shelf", "shelf", 1.2, 0.4, 2.0, "wood", against="Wall West")
        r.place("Box 1", "box", 0.7, 0.5, 0.6, "stripes")
        w = _weights(rng, 3, 2.0)
        r.spot((1.2, 4.0, 3.4), (0.0, 2.6, 1.2), 50, 0.4, 0.08, w[0], "warm white")
        r.spot((3.5, 2.5, 3.4), (3.7, 2.3, 0.0), 35, 0.15, 0.05, w[1], "neutral white")
        r.lampshade((4.3, 4.3), 1.25, 1.55, 0.22, 0.16, w[2], "amber")
        return r.spec("high ceiling (3.5 m): two spots (wall, floor) and a glowing lampshade",
                      camera=((4.7, 0.3, 1.8), (1.5, 3.5, 1.0)))
    if index == 7:
        r = _Room(7, (4.0, 6.0, 2.5), T or 128, rng, "white")
        r.shell(_room_patterns(rng, "white", ["plain", "noise", "plain", "stripes"]))
        r.place("Table", "table", 0.8, 1.4, 0.74, "plain", "mid")
        r.place("Cabinet", "cabinet", 0.5, 0.4, 0.9, "wood", "mid", against="Wall South")
        w = _weights(rng, 2, 2.2)
        r.wall_area("DISK", "Wall West", 1.5, 1.9, 0.2, 0.35, 0.35, w[0], "warm white", tilt=0.4)
        r.wall_area("DISK", "Wall East", 2.5, 1.9, 0.2, 0.35, 0.35, w[1], "cool white", tilt=0.4)
        return r.spec("white room (0.7-0.85), two wall disks 0.2 m from opposite walls",
                      camera=((3.7, 0.3, 1.6), (1.5, 5.0, 0.9)))
    if index == 8:
        r = _Room(8, (3.2, 5.0, 2.6), T or 128, rng, "mid")
        r.shell(_room_patterns(rng, "mid", ["noise", "noise", "checker", "wood"]))
        r.place("Shelf", "shelf", 1.0, 0.35, 1.7, "wood", against="Wall East")
        r.place("Box 1", "box", 0.5, 0.5, 0.4, "noise")
        w = _weights(rng, 2, 3.0)
        r.ceiling_area("SQUARE", (1.2, 2.0), 0.6, 0.6, w[0], "neutral white")
        r.lampshade((0.45, 4.5), 1.2, 1.5, 0.2, 0.15, w[1], "warm white")
        return r.spec("narrow room, square ceiling lamp and a lampshade 0.3 m from two walls",
                      camera=((3.0, 0.2, 1.6), (1.0, 4.5, 0.8)))
    if index == 9:
        r = _Room(9, (6.0, 4.0, 2.8), T or 128, rng, "mid")
        r.shell(_room_patterns(rng, "mid", ["checker", "plain", "noise", "noise"]),
                hole=("Wall West", (0.4, 0.7, 0.3, 0.8)))
        r.place("Box 1", "box", 0.6, 0.6, 0.6, "checker")
        r.place("Box 2", "box", 0.5, 0.4, 0.45, "stripes")
        r.place("Table", "table", 1.2, 0.7, 0.72, "wood")
        w = _weights(rng, 2, 2.0)
        r.sun((0.7, -0.25, -0.55), 8.0)       # a bright sun patch
        r.ceiling_area("RECTANGLE", (4.6, 1.2), 1.2, 0.4, w[1], "warm white")
        return r.spec("sun through a west window and a warm ceiling strip, boxes",
                      camera=((5.7, 3.7, 1.6), (0.5, 1.0, 0.6)))
    if index == 10:
        r = _Room(10, (8.0, 6.0, 3.0), T or 128, rng, "mid")
        r.shell(_room_patterns(rng, "mid", ["checker", "plain", "wood", "stripes"]))
        r.place("Table 1", "table", 1.6, 0.9, 0.74, "wood")
        r.place("Table 2", "table", 1.2, 0.8, 0.74, "noise")
        r.place("Cabinet", "cabinet", 1.2, 0.5, 1.4, "plain", against="Wall North")
        w = _weights(rng, 3, 3.0)
        r.point((1.4, 2.0, 2.3), 0.2, w[0], "warm white", mount="pendant")
        r.point((6.6, 4.6, 2.3), 0.1, w[1], "warm white", mount="pendant")
        r.spot((7.7, 0.3, 2.8), (4.5, 3.0, 0.0), 60, 0.5, 0.1, w[2], "cool white", mount="wall")
        return r.spec("large room, two pendant points 1:3 and a corner spot on the floor",
                      camera=((7.7, 5.7, 1.8), (2.0, 1.0, 0.5)))
    if index == 11:
        r = _Room(11, (3.5, 4.0, 2.4), T or 256, rng, "mid", furn_texel=(T or 256) // 4)
        r.shell(_room_patterns(rng, "mid", ["stripes", "wood", "checker", "noise"]),
                poster=("Wall North", (0.2, 0.45, 0.45, 0.8)))
        r.place("Cabinet", "cabinet", 0.8, 0.4, 0.8, "wood", against="Wall North")
        r.wall_area("RECTANGLE", "Wall South", 1.5, 2.0, 0.25, 0.5, 0.25, 1.0, "warm white")
        return r.spec("small room, one wall-mounted rectangle 0.25 m from the wall, 256 texels",
                      camera=((3.3, 0.2, 1.6), (1.0, 3.5, 0.8)))
    if index == 12:
        r = _Room(12, (5.5, 3.5, 2.7), T or 128, rng, "mid")
        r.shell(_room_patterns(rng, "mid", ["noise", "plain", "hstripes", "wood"]))
        r.poster_quad("Wall East", 0.8, 1.1, 0.8, 0.6)
        r.place("Shelf", "shelf", 1.4, 0.35, 1.8, "wood", against="Wall North")
        r.place("Table", "table", 1.0, 0.7, 0.72, "plain")
        w = _weights(rng, 2, 2.5)
        r.ceiling_area("DISK", (2.0, 1.2), 0.6, 0.6, w[0], "green tint")
        r.point((4.5, 2.5, 2.2), 0.12, w[1], "pink tint", mount="pendant")
        return r.spec("held out: tinted disk and pendant point, shelf, poster quad",
                      held_out=True)
    if index == 13:
        r = _Room(13, (7.0, 5.0, 3.0), T or 128, rng, "mid")
        pats = _room_patterns(rng, "mid", ["wood", "noise", "plain", "stripes"])
        pats["Floor"] = ("checker", "dark", 5)
        r.shell(pats, hole=("Wall North", (0.6, 0.85, 0.3, 0.75)))
        r.place("Table", "table", 1.5, 0.9, 0.74, "wood")
        r.place("Box 1", "box", 0.6, 0.5, 0.5, "noise")
        w = _weights(rng, 3, 3.5)
        r.sun((-0.3, -0.7, -0.65), 5.0)
        r.spot((1.0, 1.0, 2.9), (0.0, 3.0, 1.0), 45, 0.3, 0.06, w[1], "warm white")
        r.mesh_panel((4.0, 1.4, 2.99), 1.0, 0.3, w[2], "cool white")
        return r.spec("held out: sun through a north window, spot, emissive strip, dark floor",
                      camera=((6.7, 0.3, 1.8), (2.0, 4.5, 0.7)), held_out=True)
    if index == 14:
        r = _Room(14, (4.0, 4.0, 2.6), T or 128, rng, "light")
        r.shell(_room_patterns(rng, "light", ["checker", "noise", "wood", "plain"]))
        r.place("Box 1", "box", 0.5, 0.5, 0.5, "checker")
        r.place("Box 2", "box", 0.4, 0.6, 0.8, "noise")
        w = _weights(rng, 4, 4.0)
        r.ceiling_area("ELLIPSE", (1.2, 1.2), 0.8, 0.4, w[0], "neutral white")
        r.ceiling_area("RECTANGLE", (2.8, 2.8), 0.6, 0.3, w[1], "warm white")
        r.point((3.3, 0.8, 2.0), 0.05, w[2], "blue tint", mount="wall")
        r.spot((0.5, 3.5, 2.5), (2.5, 0.0, 1.0), 30, 0.2, 0.05, w[3], "amber", mount="wall")
        return r.spec("held out: four lamps 1:4 (ellipse, rect, point, spot), light albedo",
                      held_out=True)
    if index == 15:
        r = _Room(15, (6.0, 3.5, 3.3), T or 128, rng, "white")
        r.shell(_room_patterns(rng, "white", ["wood", "plain", "plain", "noise"]),
                poster=("Wall North", (0.6, 0.8, 0.4, 0.7)))
        r.place("Cabinet", "cabinet", 1.0, 0.5, 1.2, "wood", "mid", against="Wall South")
        r.place("Table", "table", 1.2, 0.8, 0.74, "noise", "mid")
        w = _weights(rng, 2, 1.8)
        r.wall_area("SQUARE", "Wall West", 1.7, 2.2, 0.3, 0.4, 0.4, w[0], "cool white")
        r.ceiling_area("RECTANGLE", (4.5, 1.8), 1.0, 0.6, w[1], "warm white")
        return r.spec("held out: white room, cool wall square and warm ceiling rectangle",
                      held_out=True)
    raise KeyError(index)


def _bug_a(texel=None):
    """Bug report (a): two white lamps of unequal power (1.64:1), table shadows on a textured
    wall."""
    rng = np.random.default_rng(2016)
    r = _Room(BUG_A, (5.0, 4.0, 2.8), texel or 128, rng, "mid")
    pats = _room_patterns(rng, "mid", ["noise", "plain", "stripes", "plain"])
    pats["Wall North"] = ("stripes", "mid", 6)
    r.shell(pats)
    # a desk 0.25 m from the textured north wall: its slab shadows the wall
    r.furniture("Table", "table", (1.5, 3.1, 0.0), (3.1, 3.75, 0.75), "wood")
    r.place("Box 1", "box", 0.5, 0.4, 0.45, "checker", region=(0.5, 4.5, 0.5, 2.0))
    r.ceiling_area("RECTANGLE", (1.5, 1.5), 1.2, 0.6, 1.64, "neutral white")
    r.ceiling_area("RECTANGLE", (3.5, 1.9), 1.2, 0.6, 1.0, "neutral white")
    return r.spec("bug report (a): two white lamps 1.64:1, table shadows on a striped wall",
                  camera=((4.7, 0.3, 1.6), (2.3, 4.0, 0.7)))


def _bug_b(texel=None):
    """Bug report (b): warm and cool lamps, checker floor, shelf."""
    rng = np.random.default_rng(2017)
    r = _Room(BUG_B, (4.5, 4.0, 2.7), texel or 128, rng, "mid")
    pats = _room_patterns(rng, "mid", ["checker", "plain", "noise", "plain"])
    pats["Floor"] = ("checker", "mid", 8)
    r.shell(pats)
    r.place("Shelf", "shelf", 1.2, 0.35, 1.8, "wood", against="Wall West")
    r.place("Box 1", "box", 0.5, 0.5, 0.4, "noise", region=(1.5, 4.0, 0.5, 3.5))
    r.ceiling_area("RECTANGLE", (1.5, 2.0), 1.0, 0.5, 1.3, "warm white")
    r.ceiling_area("DISK", (3.3, 2.2), 0.6, 0.6, 1.0, "cool white")
    return r.spec("bug report (b): warm and cool lamps, checker floor, shelf",
                  camera=((4.3, 0.3, 1.6), (0.5, 2.8, 0.8)))


def _other_program(texel=None):
    """Room 18: a model "from another program": room shell normals outward, some furniture faces
    flipped, thin single-plane panels (a table top and a partition, lit from both sides)."""
    rng = np.random.default_rng(2018)
    r = _Room(OTHER_PROGRAM, (6.0, 4.0, 2.7), texel or 128, rng, "mid")
    r.shell(_room_patterns(rng, "mid", ["wood", "plain", "noise", "checker"]))
    for s in r.surfaces:            # the whole shell points outward in the file
        s.flipped = np.ones(len(s.quads), bool)
    # partition: a single vertical plane 1.8 x 2.0 at x = 3, y 0.5..2.3, visible side -x
    ft = r.furn_texel
    part = _quad((3.0, 2.3, 0.0), (0, -1.8, 0), (0, 0, 2.0))
    r.surfaces.append(Surface("Partition", "panel", part[None],
                              np.array([[[0, 0], [1, 0], [1, 1], [0, 1]]], float) * (1 - 2 / ft) + 1 / ft,
                              albedo_pattern("hstripes", rng, ft, ft, "mid", 5), "hstripes",
                              flipped=np.array([True])))
    r.footprints.append((np.array([2.95, 0.5]), np.array([3.05, 2.3])))
    # table: top is a single plane (visible side up), legs are boxes, two leg faces flipped
    top = _quad((0.9, 2.6, 0.74), (1.4, 0, 0), (0, 0.8, 0))
    legs = []
    for lx, ly in ((0.95, 2.65), (2.19, 2.65), (0.95, 3.29), (2.19, 3.29)):
        legs += _box_faces((lx, ly, 0.0), (lx + 0.06, ly + 0.06, 0.74), skip=("-z", "+z"))
    faces = np.array([top] + legs)
    flipped = np.zeros(len(faces), bool)
    flipped[[2, 7]] = True
    r.surfaces.append(Surface("Table", "furniture", faces, _atlas_uvs(len(faces), ft),
                              albedo_pattern("wood", rng, ft, ft, "mid"), "wood", flipped))
    r.footprints.append((np.array([0.9, 2.6]), np.array([2.3, 3.4])))
    box = r.place("Box 1", "box", 0.6, 0.5, 0.5, "checker", region=(3.5, 5.5, 0.5, 3.5))
    box.flipped = np.zeros(len(box.quads), bool)
    box.flipped[[0, 4]] = True
    r.ceiling_area("RECTANGLE", (1.5, 1.4), 0.9, 0.5, 1.0, "warm white")
    r.ceiling_area("RECTANGLE", (4.5, 1.4), 0.9, 0.5, 2.0, "neutral white")
    return r.spec("from another program: shell normals outward, flipped box/leg faces, "
                  "single-plane table top and partition lit from both sides",
                  camera=((0.3, 0.3, 1.6), (4.0, 3.0, 0.8)))


def _dense_wall(texel=None):
    """Room 19: one wall at 4x the texel density (512 texels on the striped north wall with a
    poster painted into it, the other surfaces at 128): a table and a shelf against that wall
    shadow it, two ceiling lamps 1:2 (warm rectangle, neutral disk).  A pilot (``texel``) keeps
    the 4:1 ratio."""
    rng = np.random.default_rng(2019)
    T = texel or 128
    r = _Room(DENSE_WALL, (4.5, 4.0, 2.7), T, rng, "mid")
    pats = _room_patterns(rng, "mid", ["wood", "plain", "noise", "plain"])
    pats["Wall North"] = ("stripes", "mid", 8)
    r.shell(pats, poster=("Wall North", (0.14, 0.36, 0.42, 0.8)), texels={"Wall North": 4 * T})
    # a table 0.2 m from the north wall (its slab and legs shadow the wall) and a shelf against it
    r.furniture("Table", "table", (0.6, 3.1, 0.0), (2.2, 3.8, 0.75), "wood")
    r.furniture("Shelf", "shelf", (2.9, 3.63, 0.0), (3.9, 3.98, 1.8), "plain", "light")
    w = _weights(rng, 2, 2.0)
    r.ceiling_area("RECTANGLE", (1.4, 2.6), 1.0, 0.5, w[0], "warm white")
    r.ceiling_area("DISK", (3.2, 1.8), 0.6, 0.6, w[1], "neutral white")
    return r.spec("512 texels on one wall: striped north wall with a poster, table and shelf "
                  "shadows on it, warm rectangle and neutral disk 1:2",
                  camera=((4.2, 0.3, 1.6), (2.0, 4.0, 0.9)))


def _test_room(index, texel=None):
    n = texel or 32
    if index == 20:
        rng = np.random.default_rng(3020)
        r = _Room(20, (4.0, 3.5, 2.6), n, rng, "mid", furn_texel=24)
        r.shell(_room_patterns(rng, "mid", ["checker", "plain", "stripes", "noise"]))
        r.furniture("Table", "table", (1.2, 1.2, 0.0), (2.4, 2.0, 0.74), "wood")
        r.ceiling_area("RECTANGLE", (1.2, 1.6), 1.0, 0.5, 3.0, "neutral white")
        r.wall_area("DISK", "Wall East", 1.5, 1.9, 0.3, 0.4, 0.4, 1.0, "warm white")
        return r.spec("test: unequal lamps 3:1, a wall disk 0.3 m from the east wall, table",
                      camera=((0.3, 0.3, 1.6), (3.0, 2.5, 0.8)))
    if index == 21:
        rng = np.random.default_rng(3021)
        r = _Room(21, (3.5, 3.0, 2.5), n, rng, "mid", furn_texel=24)
        r.shell(_room_patterns(rng, "mid", ["wood", "plain", "noise", "plain"]))
        r.furniture("Box 1", "box", (0.8, 0.8, 0.0), (1.4, 1.3, 0.5), "checker")
        r.point((2.4, 1.0, 2.0), 0.1, 1.0, "warm white", mount="pendant")
        r.spot((0.4, 2.6, 2.3), (0.0, 0.6, 0.8), 45, 0.3, 0.05, 1.6, "cool white", mount="wall")
        return r.spec("test: a pendant point lamp and a spot on the west wall, box",
                      camera=((3.3, 0.2, 1.6), (0.8, 2.5, 0.8)))
    if index == 22:
        rng = np.random.default_rng(3022)
        r = _Room(22, (3.0, 4.0, 2.7), n, rng, "light", furn_texel=24)
        r.shell(_room_patterns(rng, "light", ["checker", "plain", "plain", "stripes"]))
        r.furniture("Shelf", "shelf", (0.02, 1.2, 0.0), (0.37, 2.4, 1.6), "wood", "mid")
        r.mesh_panel((1.8, 2.5, 2.69), 0.6, 0.3, 1.0, "cool white")
        r.ceiling_area("SQUARE", (1.5, 1.0), 0.4, 0.4, 2.0, "warm white")
        return r.spec("test: warm square and cool emissive panel 1:2, shelf",
                      camera=((2.8, 0.2, 1.6), (0.5, 3.5, 0.8)))
    raise KeyError(index)


def room_spec(index: int, texel: int | None = None) -> RoomSpec:
    """The room of ``index`` (see FAMILY); ``texel`` overrides the wall texture size (furniture,
    posters and per-wall texel overrides scale with it) for low-resolution pilots."""
    index = int(index)
    if index in SEEDED:
        spec = _seeded(index, texel)
    elif index == BUG_A:
        spec = _bug_a(texel)
    elif index == BUG_B:
        spec = _bug_b(texel)
    elif index == OTHER_PROGRAM:
        spec = _other_program(texel)
    elif index == DENSE_WALL:
        spec = _dense_wall(texel)
    elif index in TEST_ROOMS:
        spec = _test_room(index, texel)
    else:
        raise KeyError(f"no room {index}; FAMILY = {FAMILY}")
    spec.held_out = index in HELD_OUT
    spec.pilot = texel is not None
    return spec


# -- bpy-free helpers -------------------------------------------------------------------------------

def coverage(surface: Surface, shape=None) -> np.ndarray:
    """(H, W) bool: texels whose centre lies inside one of the surface's UV rectangles."""
    h, w = surface.albedo.shape[:2] if shape is None else shape
    u = (np.arange(w) + 0.5) / w
    v = (np.arange(h) + 0.5) / h
    m = np.zeros((h, w), bool)
    for q in surface.uvs:
        u0, u1, v0, v1 = q[:, 0].min(), q[:, 0].max(), q[:, 1].min(), q[:, 1].max()
        m[np.ix_((v > v0) & (v < v1), (u > u0) & (u < u1))] = True
    return m


def spec_hash(spec: RoomSpec) -> str:
    """sha256 of everything the bakes depend on (geometry, UVs, albedo, flips, lamps)."""
    h = hashlib.sha256()

    def canon(x):
        """Text independent of numpy's print options (colour-science changes them) and of the
        sign of zero."""
        if isinstance(x, (tuple, list)):
            return "(" + ",".join(canon(v) for v in x) + ")"
        if isinstance(x, dict):
            return "{" + ",".join(f"{canon(k)}:{canon(v)}" for k, v in sorted(x.items())) + "}"
        if isinstance(x, (bool, np.bool_)) or x is None or isinstance(x, str):
            return repr(x if not isinstance(x, np.bool_) else bool(x))
        if isinstance(x, (int, float, np.integer, np.floating)):
            return f"{round(float(x), 6) + 0.0:.6f}"
        raise TypeError(type(x))

    def add(x):
        if isinstance(x, np.ndarray):
            x = np.ascontiguousarray(x)
            if x.dtype.kind == "f":
                x = np.round(x.astype(np.float64), 6) + 0.0
            h.update(f"{x.dtype}{x.shape}".encode())
            h.update(x.tobytes())
        else:
            h.update(canon(x).encode())

    add((GENERATOR_VERSION, spec.index, tuple(round(float(v), 6) for v in spec.size), spec.texel))
    for s in spec.surfaces:
        add((s.name, s.kind))
        add(s.quads)
        add(s.uvs)
        add(np.ascontiguousarray(s.albedo, np.float32))
        add(None if s.flipped is None else np.asarray(s.flipped, bool))
    for lp in spec.lamps:
        add((lp.name, lp.type, lp.shape, round(lp.power, 6), tuple(round(c, 6) for c in lp.colour),
             round(lp.size, 6), round(lp.size_y, 6), round(lp.radius, 6), round(lp.spot_size, 6),
             round(lp.spot_blend, 6), round(lp.angle, 6), lp.two_sided))
        add(np.asarray(lp.location, float))
        add(np.asarray(lp.rotation, float))
        add(None if lp.quads is None else np.asarray(lp.quads, float))
    add(spec.window)
    return h.hexdigest()


def room_summary(spec: RoomSpec) -> dict:
    W, D, H = spec.size
    return {"index": spec.index, "name": spec.name, "description": spec.description,
            "size": [W, D, H], "texel": spec.texel, "held_out": spec.held_out,
            "objects": spec.objects, "lamps": [lp.summary() for lp in spec.lamps]}


def texel_points(surface: Surface):
    """World positions (H, W, 3) and unit visible normals (H, W, 3) of the texel centres, and the
    coverage mask (H, W): the UV rectangle of each quad maps bilinearly onto its corners."""
    h, w = surface.albedo.shape[:2]
    P = np.zeros((h, w, 3))
    N = np.zeros((h, w, 3))
    m = np.zeros((h, w), bool)
    u = (np.arange(w) + 0.5) / w
    v = (np.arange(h) + 0.5) / h
    for q, uv, n in zip(surface.quads, surface.uvs, surface.normals):
        u0, u1, v0, v1 = uv[0, 0], uv[1, 0], uv[0, 1], uv[3, 1]
        cols = np.nonzero((u > min(u0, u1)) & (u < max(u0, u1)))[0]
        rows = np.nonzero((v > min(v0, v1)) & (v < max(v0, v1)))[0]
        if not len(cols) or not len(rows):
            continue
        ss = ((u[cols] - u0) / (u1 - u0))[None, :, None]
        tt = ((v[rows] - v0) / (v1 - v0))[:, None, None]
        P[np.ix_(rows, cols)] = ((1 - ss) * (1 - tt) * q[0] + ss * (1 - tt) * q[1]
                                 + ss * tt * q[2] + (1 - ss) * tt * q[3])
        N[np.ix_(rows, cols)] = n
        m[np.ix_(rows, cols)] = True
    return P, N, m


def lamp_polygon(lamp: Lamp, k: int = 48) -> np.ndarray:
    """(k or 4, 3) outline of an area lamp in world space (ellipse / disk: a k-gon), counter-
    clockwise around its emitting direction."""
    R, c = np.asarray(lamp.rotation, float), np.asarray(lamp.location, float)
    if lamp.shape in ("DISK", "ELLIPSE"):
        a = np.linspace(0, 2 * np.pi, k, endpoint=False)
        local = np.stack([0.5 * lamp.size * np.cos(a), -0.5 * lamp.size_y * np.sin(a)], 1)
    else:
        sx, sy = lamp.size / 2, lamp.size_y / 2
        local = np.array([[-sx, -sy], [-sx, sy], [sx, sy], [sx, -sy]])
    return c + local[:, :1] * R[:, 0] + local[:, 1:] * R[:, 1]


def direct_bake(spec: RoomSpec, lamp: Lamp, surface: Surface) -> np.ndarray:
    """UNOCCLUDED direct light of ``lamp`` on ``surface`` in bake units (albedo x E / pi, colour
    included), (H, W, 3); the sun's only through the window hole (strength x cos).  Units as Blender 5.0 / Cycles
    (checked against the bakes in tests/test_family_data.py): area lights (Normalize) exitance
    P / A; point and spot lights intensity P / (4 pi) W/sr (spot: inside the cone, smoothstep
    blend); emissive meshes exitance pi x Strength per emitting side."""
    from relight_addon.core.geometry.formfactor import point_to_polygon  # noqa: PLC0415
    P, N, m = texel_points(surface)
    pts, nrm = P[m], N[m]
    E = np.zeros(len(pts))
    if lamp.type == "SUN":
        # through the window hole only (the rest of the shell is closed); no other occluder
        if spec.window is None:
            raise ValueError("a sun needs a window")
        wall = spec.surface(spec.window["wall"])
        u0, u1, v0, v1 = spec.window["uv"]
        q = wall.quads[0]                     # the strip below the hole spans the wall's width
        o = q[0] - 0 * q[1]
        du = q[1] - q[0]
        dv = (wall.quads[1][3] - wall.quads[0][0]) if len(wall.quads) > 1 else q[3] - q[0]
        n = wall.normals[0]
        to_sun = -lamp.direction
        denom = to_sun @ n
        t = ((o - pts) @ n) / (denom if abs(denom) > 1e-12 else np.inf)
        hit = pts + t[:, None] * to_sun
        a = ((hit - o) @ du) / (du @ du)
        b = ((hit - o) @ dv) / (dv @ dv)
        inside = (t > 0) & (a > u0) & (a < u1) & (b > v0) & (b < v1) & (denom < 0)
        E = np.where(inside, lamp.power * np.clip(nrm @ to_sun, 0, None), 0.0)
    elif lamp.type == "AREA":
        poly = lamp_polygon(lamp)
        area = np.pi * lamp.size * lamp.size_y / 4 if lamp.shape in ("DISK", "ELLIPSE") else lamp.size * lamp.size_y
        F = point_to_polygon(pts, nrm, np.broadcast_to(poly, (len(pts), *poly.shape)),
                             np.broadcast_to(lamp.direction, pts.shape))
        E = lamp.power / area * F
    elif lamp.type == "MESH":
        for q in lamp.quads:
            n = np.cross(q[2] - q[0], q[3] - q[1])
            n /= np.linalg.norm(n)
            sides = (n, -n) if lamp.two_sided else (n,)
            for sn in sides:
                poly = q if sn is n else q[::-1]
                E += np.pi * lamp.power * point_to_polygon(
                    pts, nrm, np.broadcast_to(poly, (len(pts), 4, 3)), np.broadcast_to(sn, pts.shape))
    else:  # POINT, SPOT
        d = np.asarray(lamp.location) - pts
        r2 = (d * d).sum(1)
        dn = d / np.sqrt(r2)[:, None]
        cos_r = np.clip((dn * nrm).sum(1), 0, None)
        E = lamp.power / (4 * np.pi) * cos_r / r2
        if lamp.type == "SPOT":
            cos_a = (-dn * lamp.direction).sum(1)
            c0 = np.cos(lamp.spot_size / 2)
            smooth = (1 - c0) * lamp.spot_blend
            t = np.clip((cos_a - c0) / max(smooth, 1e-12), 0, 1)
            E *= np.where(cos_a <= c0, 0.0, t * t * (3 - 2 * t) if smooth > 0 else 1.0)
    out = np.zeros(surface.albedo.shape)
    out[m] = surface.albedo[m] * np.asarray(lamp.colour)[None] * E[:, None] / np.pi
    return out


# -- the cache (bpy-free) ----------------------------------------------------------------------------

def bake_dir(index: int) -> str:
    return os.path.join(TEST_BAKE_DIR if index in TEST_ROOMS else BAKE_DIR, f"room_{index:02d}")


def save_images(path: str, images: dict):
    """{name: (H, W, 3) float} -> one compressed file of float16 texels (see load_images).

    Format (smallest of the candidates measured in benchmarks/family/README.md): the float16
    bytes of every image, split into high and low byte planes (the exponent bytes compress
    well, the noisy mantissa bytes do not), lzma-compressed, in an .npz with the shapes."""
    import lzma  # noqa: PLC0415
    names = list(images)
    arrs = [np.ascontiguousarray(np.asarray(images[n], np.float32).astype(np.float16)) for n in names]
    flat = np.concatenate([a.ravel() for a in arrs]).view(np.uint8).reshape(-1, 2)
    planes = np.ascontiguousarray(flat.T).tobytes()
    blob = lzma.compress(planes, preset=9 | lzma.PRESET_EXTREME)
    tmp = path + ".tmp.npz"
    np.savez(tmp, names=np.array(names), shapes=np.array([a.shape for a in arrs]),
             data=np.frombuffer(blob, np.uint8))
    os.replace(tmp, path)


def load_images(path: str) -> dict:
    import lzma  # noqa: PLC0415
    with np.load(path) as z:
        names, shapes, blob = list(z["names"]), z["shapes"], z["data"].tobytes()
    planes = np.frombuffer(lzma.decompress(blob), np.uint8).reshape(2, -1)
    flat = np.ascontiguousarray(planes.T).view(np.float16).ravel()
    out, k = {}, 0
    for n, s in zip(names, shapes):
        size = int(np.prod(s))
        out[str(n)] = flat[k:k + size].reshape(s).astype(np.float32)
        k += size
    return out


class SpecMismatch(RuntimeError):
    pass


@dataclass
class Bakes:
    """Cached Cycles bakes of one room: ``photo[obj]`` (all lamps, seed 0), ``lamps[lamp][obj]``
    (each lamp alone at its spec power, seed 1), ``meta`` (the JSON), ``spec``."""
    spec: RoomSpec
    photo: dict
    lamps: dict
    meta: dict

    def truth(self, intensities: dict | None = None) -> dict:
        """{obj: sum_k I_k bake_k}; lamps missing from ``intensities`` keep factor 1."""
        intensities = intensities or {}
        unknown = set(intensities) - set(self.lamps)
        if unknown:
            raise KeyError(f"unknown lamps {sorted(unknown)}; lamps: {list(self.lamps)}")
        return {o: sum(float(intensities.get(k, 1.0)) * self.lamps[k][o] for k in self.lamps)
                for o in self.photo}

    def masks(self) -> dict:
        return {s.name: coverage(s) for s in self.spec.surfaces}


def load_bakes(index: int, check_hash: bool = True) -> Bakes:
    """The cached bakes of room ``index`` (bpy-free).  Raises FileNotFoundError when the room was
    not baked yet and SpecMismatch when the generator changed since the bake (re-run
    ``benchmarks/family_bakes.py --rooms <index>``)."""
    spec = room_spec(index)
    d = bake_dir(index)
    meta_path = os.path.join(d, "bake.json")
    if not os.path.exists(meta_path):
        raise FileNotFoundError(f"room {index} is not baked ({meta_path}); "
                                f"run benchmarks/family_bakes.py --rooms {index}")
    with open(meta_path) as f:
        meta = json.load(f)
    if check_hash and meta["spec_hash"] != spec_hash(spec):
        raise SpecMismatch(f"room {index}: bakes were made for spec {meta['spec_hash'][:12]}, "
                           f"the generator now gives {spec_hash(spec)[:12]}; re-bake it")
    photo = load_images(os.path.join(d, "photo.npz"))
    lamps = {}
    for lp in spec.lamps:
        lamps[lp.name] = load_images(os.path.join(d, meta["lamp_files"][lp.name]))
    return Bakes(spec, photo, lamps, meta)


def baked_rooms() -> list:
    return [i for i in FAMILY if os.path.exists(os.path.join(bake_dir(i), "bake.json"))]


# -- noise floor (bpy-free) --------------------------------------------------------------------------

LUM = np.array([0.2126, 0.7152, 0.0722])


def noise_floor(photo: dict, truth: dict, masks: dict) -> dict:
    """CIEDE2000 between photo and truth over covered texels, colours divided by the 99th
    percentile of the truth's luminance (as tests/test_shadowfree.py::Office.de)."""
    from relight_addon.core.texture.colour import delta_e_2000, linear_rgb_to_lab  # noqa: PLC0415
    names = list(masks)
    P = np.concatenate([photo[n][masks[n]] for n in names]).astype(np.float64)
    T = np.concatenate([truth[n][masks[n]] for n in names]).astype(np.float64)
    white = float(np.percentile(T @ LUM, 99))
    d = delta_e_2000(linear_rgb_to_lab(np.clip(P / white, 0, None)),
                     linear_rgb_to_lab(np.clip(T / white, 0, None)))
    return {"mean": float(d.mean()), "p95": float(np.percentile(d, 95)), "white": white,
            "texels": int(len(d))}


# -- Blender -----------------------------------------------------------------------------------------

def _emission_material(bpy, name, colour, strength, two_sided):
    """Emission (front only unless two_sided: a Backfacing mix with a black diffuse)."""
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    nt = mat.node_tree
    for nd in list(nt.nodes):
        nt.nodes.remove(nd)
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    em = nt.nodes.new("ShaderNodeEmission")
    em.name = em.label = "Lamp Emission"
    em.inputs["Color"].default_value = (*colour, 1.0)
    em.inputs["Strength"].default_value = float(strength)
    if two_sided:
        nt.links.new(em.outputs[0], out.inputs["Surface"])
    else:
        geo = nt.nodes.new("ShaderNodeNewGeometry")
        black = nt.nodes.new("ShaderNodeBsdfDiffuse")
        black.inputs["Color"].default_value = (0, 0, 0, 1)
        mix = nt.nodes.new("ShaderNodeMixShader")
        nt.links.new(geo.outputs["Backfacing"], mix.inputs["Fac"])
        nt.links.new(em.outputs[0], mix.inputs[1])
        nt.links.new(black.outputs[0], mix.inputs[2])
        nt.links.new(mix.outputs[0], out.inputs["Surface"])
    if hasattr(mat, "emission_sampling"):
        mat.emission_sampling = "FRONT_BACK" if two_sided else "FRONT"
    return mat


def _mesh_object(bpy, name, quads, uvs=None, flip=None):
    nq = len(quads)
    q = np.array(quads, float)
    uv = None if uvs is None else np.array(uvs, float)
    if flip is not None:
        q[flip] = q[flip][:, ::-1]
        if uv is not None:
            uv[flip] = uv[flip][:, ::-1]
    # Degenerate quads (a, b, c, c) are triangles (scenes.scan): made as three-corner faces.
    k = 3 if nq and np.array_equal(q[:, 2], q[:, 3]) else 4
    q = q[:, :k]
    me = bpy.data.meshes.new(name)
    me.vertices.add(nq * k)
    me.vertices.foreach_set("co", q.reshape(-1).astype(np.float32))
    me.loops.add(nq * k)
    me.loops.foreach_set("vertex_index", np.arange(nq * k, dtype=np.int32))
    me.polygons.add(nq)
    me.polygons.foreach_set("loop_start", np.arange(0, nq * k, k, dtype=np.int32))
    if uv is not None:
        layer = me.uv_layers.new(name="UVMap")
        layer.data.foreach_set("uv", uv[:, :k].reshape(-1, 2).astype(np.float32).ravel())
    me.update()
    obj = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def build_room(spec: RoomSpec, orientation: str = "visible", textures: dict | None = None) -> dict:
    """Create the room in the current, factory-empty scene.  orientation "visible": every quad
    faces its photographed side (what is baked); "file": quads with ``Surface.flipped`` are
    reversed (room 18, what another program would export).  textures: {object: (H, W, 3)
    linear} used as the images instead of the true albedo, e.g. ``load_bakes(i).photo`` for the
    "photographed" model the add-on is given.  Returns {"objects", "lamps", "albedo_images",
    "materials", "camera"}."""
    import bpy  # noqa: PLC0415
    from mathutils import Matrix, Vector  # noqa: PLC0415

    from scenes.office import _diffuse_material, _new_image  # noqa: PLC0415
    if orientation not in ("visible", "file"):
        raise ValueError(orientation)
    scene = bpy.context.scene
    objects, albedo_images, materials = [], {}, {}
    for s in spec.surfaces:
        flip = s.flipped if (orientation == "file" and s.flipped is not None) else None
        obj = _mesh_object(bpy, s.name, s.quads, s.uvs, flip)
        img = _new_image(bpy, f"{s.name} albedo" if textures is None else f"{s.name} photo",
                         s.albedo if textures is None else np.asarray(textures[s.name], np.float32))
        mat = _diffuse_material(bpy, f"{s.name} material", img)
        nt = mat.node_tree
        uvn = nt.nodes.new("ShaderNodeUVMap")
        uvn.uv_map = "UVMap"
        uvn.location = (-650, 200)
        nt.links.new(uvn.outputs["UV"], nt.nodes["Albedo"].inputs["Vector"])
        obj.data.materials.append(mat)
        objects.append(obj.name)
        albedo_images[obj.name] = img.name
        materials[obj.name] = mat.name

    lamps = []
    for lp in spec.lamps:
        if lp.type == "MESH":
            obj = _mesh_object(bpy, lp.name, lp.quads)
            obj.data.materials.append(_emission_material(bpy, f"{lp.name} emission", lp.colour,
                                                         lp.power, lp.two_sided))
            obj["relight_lamp"] = True
            lamps.append(obj.name)
            continue
        light = bpy.data.lights.new(lp.name, lp.type)
        light.energy = float(lp.power)
        light.color = tuple(lp.colour)
        if lp.type == "AREA":
            light.shape = lp.shape
            light.size = float(lp.size)
            light.size_y = float(lp.size_y)
        elif lp.type in ("POINT", "SPOT"):
            light.shadow_soft_size = float(lp.radius)
            if lp.type == "SPOT":
                light.spot_size = float(lp.spot_size)
                light.spot_blend = float(lp.spot_blend)
        elif lp.type == "SUN":
            light.angle = float(lp.angle)
        obj = bpy.data.objects.new(lp.name, light)
        M = Matrix(np.asarray(lp.rotation, float).tolist()).to_4x4()
        M.translation = Vector(tuple(lp.location))
        obj.matrix_world = M
        scene.collection.objects.link(obj)
        lamps.append(obj.name)

    cam_data = bpy.data.cameras.new("Room Camera")
    cam_data.lens = 18.0
    cam = bpy.data.objects.new("Room Camera", cam_data)
    cam.location = spec.camera_location
    d = np.subtract(spec.camera_target, spec.camera_location)
    cam.rotation_euler = Vector(d).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.engine = "CYCLES"
    scene.world = None
    bpy.context.view_layer.update()
    return {"objects": objects, "lamps": lamps, "albedo_images": albedo_images,
            "materials": materials, "camera": cam.name}
