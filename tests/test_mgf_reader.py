"""MGF reader (benchmarks/mgf.py) against analytic geometry."""
import math
import os
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "benchmarks"))

import mgf  # noqa: E402
from relight_addon.core.scene import quad_area_normal  # noqa: E402
from relight_addon.core.texture.colour import luminance  # noqa: E402


SQUARE = """
v a =
\tp 0 0 0
v b =
\tp 1 0 0
v c =
\tp 1 1 0
v d =
\tp 0 1 0
"""


def _read(tmp_path, text, name="scene.mgf", **kw):
    path = tmp_path / name
    path.write_text(text)
    return mgf.read_mgf(path, **kw)


def _area(scene):
    return quad_area_normal(scene.corners)[0]


def _coverage(scene, point):
    """How many patches (triangles or convex quads in the z = 0 plane) contain ``point``."""
    count = 0
    for quad in scene.corners[:, :, :2]:
        edges = np.roll(quad, -1, axis=0) - quad
        inside = [e[0] * (point - a)[1] - e[1] * (point - a)[0] > 0
                  for a, e in zip(quad, edges) if np.any(e)]
        count += all(inside)
    return count


def _inscribed_sphere_area(r, n):
    """Area of mgflib's sphere: 2n bands of 4n planar trapezoids (triangles at the poles) with
    their corners on the sphere, 90 / n degrees apart in latitude and longitude."""
    half = math.pi / (4 * n)                       # half the longitude step
    total = 0.0
    for i in range(1, 2 * n + 1):
        t0, t1 = (i - 1) * math.pi / (2 * n), i * math.pi / (2 * n)
        ra, rb = r * math.sin(t0), r * math.sin(t1)
        height = math.hypot(r * (math.cos(t0) - math.cos(t1)), (ra - rb) * math.cos(half))
        total += 4 * n * (ra + rb) * math.sin(half) * height
    return total


@pytest.mark.parametrize("n", [4, 5])
def test_sphere_area_is_the_inscribed_polyhedron(tmp_path, n):
    """Corners on the sphere: area exactly that of the inscribed polyhedron, below 4 pi r^2 by
    less than the chord error (pi / 4n)^2 of a 90 / n degree step; faces all point outwards."""
    r = 0.7
    path = tmp_path / "sphere.mgf"
    path.write_text("v c =\n\tp 1 2 3\nsph c 0.7\n")
    model = mgf.parse_mgf(path, nqcdivs=n)
    assert model.faces == 8 * n * n
    area, normal = quad_area_normal(model.corners)
    assert area.sum() == pytest.approx(_inscribed_sphere_area(r, n), rel=1e-12)
    deficit = 1 - area.sum() / (4 * math.pi * r * r)
    assert 0 < deficit < (math.pi / (4 * n)) ** 2
    outward = np.einsum("ij,ij->i", normal, model.corners.mean(axis=1) - [1, 2, 3])
    assert np.all(outward > 0)


def test_square_with_a_hole_written_with_a_seam(tmp_path):
    """f o0 o1 o2 o3 h0 h1 h2 h3 h0 o3: the hole (opposite order) joined by a seam walked twice.
    A fan from o0 would cover the hole; ear clipping leaves it empty."""
    text = """
v o0 =
\tp 0 0 0
v o1 =
\tp 4 0 0
v o2 =
\tp 4 4 0
v o3 =
\tp 0 4 0
v h0 =
\tp 1 2.5 0
v h1 =
\tp 3 2.5 0
v h2 =
\tp 3 1 0
v h3 =
\tp 1 1 0
f o0 o1 o2 o3 h0 h1 h2 h3 h0 o3
"""
    scene = _read(tmp_path, text)
    assert _area(scene).sum() == pytest.approx(16 - 3)
    assert np.allclose(quad_area_normal(scene.corners)[1], [0, 0, 1])
    assert _coverage(scene, np.array([2.0, 1.75])) == 0           # in the hole
    for point in ([0.3, 0.6], [3.6, 3.3], [2.1, 0.4], [0.4, 2.2], [3.7, 1.9], [2.2, 3.4]):
        assert _coverage(scene, np.array(point)) == 1


def test_non_convex_face_is_ear_clipped(tmp_path):
    """An L given from a corner next to the reflex one: a fan from there would cover the notch."""
    text = """
v p0 =
\tp 0 0 0
v p1 =
\tp 2 0 0
v p2 =
\tp 2 1 0
v p3 =
\tp 1 1 0
v p4 =
\tp 1 2 0
v p5 =
\tp 0 2 0
f p2 p3 p4 p5 p0 p1
"""
    scene = _read(tmp_path, text)
    assert _area(scene).sum() == pytest.approx(3.0)
    assert np.allclose(quad_area_normal(scene.corners)[1], [0, 0, 1])
    assert _coverage(scene, np.array([1.5, 1.5])) == 0            # the notch
    for point in ([0.3, 0.6], [1.7, 0.2], [0.4, 1.3], [0.2, 1.9]):
        assert _coverage(scene, np.array(point)) == 1


def test_xf_scales_and_moves_and_pops(tmp_path):
    text = SQUARE + "xf -s 2 -t 5 0 1\nf a b c d\nxf\nf a b c d\n"
    scene = _read(tmp_path, text)
    area = _area(scene)
    assert area[0] == pytest.approx(4.0) and area[1] == pytest.approx(1.0)
    assert np.allclose(scene.corners[0].mean(axis=0), [6, 1, 1])
    assert np.allclose(scene.corners[1].mean(axis=0), [0.5, 0.5, 0])


def test_xf_repeat_rotation_and_mirror(tmp_path):
    """-i 2 repeats what follows it; a mirror keeps the face on its side (vertex order reversed)."""
    text = SQUARE + ("xf -t 1 0 0 -i 2 -rz 90\nf a b c d\nxf\n"
                     "xf -mx\nf a b c d\nxf\n")
    scene = _read(tmp_path, text)
    assert np.allclose(scene.corners[0].mean(axis=0), [-1.5, -0.5, 0])
    assert np.allclose(scene.corners[1].mean(axis=0), [-0.5, 0.5, 0])
    assert np.allclose(quad_area_normal(scene.corners)[1], [0, 0, 1])


def test_include_with_transform_and_redefined_vertex(tmp_path):
    """i is relative to the including file and carries its own xf; a vertex redefined later is
    used as it is when the face is read."""
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "square.mgf").write_text(SQUARE + "f a b c d\n")
    text = "i parts/square.mgf -t 0 0 3\n" + SQUARE + "f a b c d\nv c =\n\tp 2 2 0\nf a b c d\n"
    scene = _read(tmp_path, text)
    assert np.allclose(scene.corners[0, :, 2], 3)
    assert np.allclose(scene.corners[1, :, 2], 0)
    assert _area(scene)[2] == pytest.approx(2.0)


@pytest.mark.parametrize("radius, sign", [(0.5, 1), (-0.5, -1)])
def test_cylinder_normals_follow_the_sign_of_the_radius(tmp_path, radius, sign):
    text = f"v a =\n\tp 0 0 0\nv b =\n\tp 0 0 2\ncyl a {radius} b\n"
    scene = _read(tmp_path, text)
    assert scene.n_patches == 4 * mgf.NQCDIVS
    _, normal = quad_area_normal(scene.corners)
    radial = scene.corners.mean(axis=1)[:, :2]
    assert np.all(sign * np.einsum("ij,ij->i", normal[:, :2], radial) > 0)
    assert np.allclose(normal[:, 2], 0, atol=1e-12)


def test_materials_colours_and_lamps(tmp_path):
    text = SQUARE + """
m white =
\tc
\t\tcxy 0.333333 0.333333
\trd 0.6
m tinted = white
\tc
\t\tcxy 0.45 0.41
\trd 0.3
m bulb =
\tc
\t\tcxy 0.4 0.4
\ted 100
o wall
m white
f a b c d
m tinted
xf -t 0 0 1
f a b c d
xf
o
o lamp
m bulb
xf -t 0 0 2
f a b c d
xf
o
"""
    scene = _read(tmp_path, text)
    assert list(scene.lamp) == [-1, -1, 0] and scene.lamp_names == ["lamp"]
    assert np.allclose(scene.rho[0], 0.6, rtol=1e-5)           # MGF's white stays grey
    assert luminance(scene.rho[1]) == pytest.approx(0.3)
    assert scene.rho[1][0] > scene.rho[1][2]                   # a warm colour
    assert np.all(scene.rho[2] == 0)
    assert luminance(scene.emission[2]) == pytest.approx(100.0)
    assert np.all(scene.emission[:2] == 0)
    assert scene.group[0] == scene.group[1] != scene.group[2]
    one = _read(tmp_path, text, lamps="one")
    assert list(one.lamp) == [-1, -1, 0] and len(one.lamp_names) == 1


def test_unsupported_entity_is_an_error(tmp_path):
    with pytest.raises(mgf.MgfError, match=r"scene\.mgf:2: unsupported entity 'fh'"):
        _read(tmp_path, "v a =\nfh a a a\n")
