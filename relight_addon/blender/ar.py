# SPDX-License-Identifier: GPL-3.0-or-later
"""AR mode's Set Up and Update: the scene's own render becomes the composite over the photo.

Three hand-offs, as the relighting pipeline's (pipeline.py):

1. :func:`prepare` (main thread) reads the AR scene (ar_read.py; bad input: PipelineError, one
   sentence, nothing changed) into an :class:`ARJob`;
2. :meth:`ARJob.compute` (any thread, bpy-free): the environment's lighting
   (core/ar/lighting.py: lights, irradiance and cap-filtered tables), unless the same map was
   prepared before, and the sphere sets of the virtual objects whose mesh changed
   (core/relight/spheres.py);
3. :meth:`ARJob.write` (main thread): the tables image, the node groups (ar_nodes.py), the
   receivers' materials, the compositor, the passes and the render settings (ar_write.py),
   the state.

After it a render (Cycles or EEVEE) is the composite, from the .blend alone; moving or
animating the objects needs nothing (drivers), a new object or a new environment needs Update
(``bpy.ops.relight.update()`` comes here once the scene is set up for AR).

The scene's ``relight_ar`` ID property is the state: the environment's hash, its lights, the
previous render settings, the objects' fits (on their shadow groups).
"""
from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.ar.ground import ground_plane
from . import ar_draw, ar_nodes, ar_read, ar_write, ids
from .images import MapWriter
from .pipeline import Outcome, PipelineError

STATE = ids.AR_STATE
_LIGHTING = {}           # env hash -> EnvironmentLighting prepared in this session
LIGHTINGS_KEPT = 3       # maps kept in memory (about 30 MB each)
_FITS = {}               # fit hash -> (centres, radii, hull) fitted in this session
FITS_KEPT = 64           # fits kept in memory (a few KB each)


def is_set_up(scene) -> bool:
    return scene is not None and STATE in scene and ids.scene_key(scene) is not None


def state(scene) -> dict:
    st = scene.get(STATE)
    return st.to_dict() if hasattr(st, "to_dict") else dict(st or {})


def fit_hash(triangles, n):
    h = hashlib.sha1(np.ascontiguousarray(triangles, np.float32).tobytes())
    h.update(f"{n}/seed0".encode())
    return h.hexdigest()


@dataclass
class ARResult:
    lighting: object                       # EnvironmentLighting, or False (the stored one holds)
    fits: dict                             # object name -> (centres, radii, hull, hash)
    view: object = None                    # receiver_view.ReceiverView, or None (kept)
    seconds: dict = field(default_factory=dict)


class ARJob:
    """One Set Up or Update of AR mode, read and ready to compute (see the module docstring)."""
    kind = "ar"

    def __init__(self, inp, how, lighting, todo, kept, view_hash, view_needed):
        self.inp = inp
        self.view_hash = view_hash
        self.view_needed = view_needed      # the receiver view must be traced again
        self.how = how                      # "setup" or "update"
        self.action = "ar"
        self.lighting = lighting            # prepared before (same map), or None
        self.todo = todo                    # [(ObjectInput, hash)] to fit
        self.kept = kept                    # {name: fit} taken from the existing groups
        self.t0 = time.perf_counter()

    def compute(self, progress=None):
        """The environment's lighting (when it changed) and the new sphere fits (bpy-free)."""
        from ..core.ar.lighting import prepare_environment
        from ..core.progress import report, reporting
        from ..core.relight.spheres import fit_spheres, silhouette_sphere
        seconds = {}
        with reporting(progress):
            lighting = self.lighting
            if lighting is None:
                report(0.0, "Reading the environment: lights, irradiance, cap tables", 0.5)
                t = time.perf_counter()
                lighting = prepare_environment(self.inp.env_pixels, bottom_row_first=True)
                seconds["environment"] = time.perf_counter() - t
            view = None
            if self.view_needed:
                from ..core.ar.receiver_view import receiver_view
                report(0.5, "Tracing what the photographed set hides from itself", 0.8)
                t = time.perf_counter()
                lights = [lt for lt in lighting.lights if lt.solid_angle > 0][:4]
                view = receiver_view(self.inp.model, self.inp.receiver_triangles, lights,
                                     lighting.residual, self.inp.view_size)
                seconds["receiver view"] = time.perf_counter() - t
            fits = dict(self.kept)
            for k, (o, h) in enumerate(self.todo):
                report(0.8 + 0.2 * k / len(self.todo), f"Fitting spheres to '{o.obj.name}'",
                       0.8 + 0.2 * (k + 1) / len(self.todo))
                t = time.perf_counter()
                centres, radii = fit_spheres(o.triangles, o.spheres, seed=0)
                fits[o.obj.name] = (centres, radii, silhouette_sphere(o.triangles), h)
                if len(_FITS) >= FITS_KEPT:
                    _FITS.pop(next(iter(_FITS)))
                _FITS[h] = fits[o.obj.name][:3]
                seconds[f"fit {o.obj.name}"] = time.perf_counter() - t
        return ARResult(lighting, fits, view, seconds)

    def write(self, context, result) -> Outcome:
        return write(context, self, result)


def _group_fit(ng):
    a = ids.array(ng.get("relight_ar_spheres", [])).reshape(-1, 4)
    h = list(ng.get("relight_ar_hull", [0, 0, 0, 0]))
    return (a[:, :3], a[:, 3], (np.asarray(h[:3], float), float(h[3])),
            ng.get(ar_nodes.FIT_KEY, ""))


# AR's composite is a compositor node group (``scene.compositing_node_group``) whose Map UV
# nodes take their interpolation and extension as inputs: Blender 5.0's compositor.  4.5's
# (``scene.node_tree``, those settings as node properties) is not written.
AR_MIN_BLENDER = (5, 0, 0)


def unsupported_reason() -> str | None:
    """Why this Blender cannot run AR mode, or None."""
    if tuple(bpy.app.version) < AR_MIN_BLENDER:
        return (f"AR mode needs Blender {'.'.join(map(str, AR_MIN_BLENDER[:2]))} or later "
                f"(its compositor); this is Blender {bpy.app.version_string.split()[0]}")
    return None


def prepare(context, how="setup") -> ARJob:
    """Read ``context.scene`` for AR mode (ar_read.read); PipelineError on bad input or a
    Blender older than AR_MIN_BLENDER."""
    reason = unsupported_reason()
    if reason:
        raise PipelineError(reason)
    inp = ar_read.read(context, require_objects=how == "setup")
    scene = context.scene
    st = state(scene) if is_set_up(scene) else {}
    key = ids.scene_key(scene)
    lighting = _LIGHTING.get(inp.env_hash)
    groups = ar_nodes.shadow_groups(key) if key is not None else {}
    todo, kept = [], {}
    for o in inp.objects:
        h = fit_hash(o.triangles, o.spheres)
        g = groups.get(o.obj.name)
        if g is not None and g.get(ar_nodes.FIT_KEY) == h:
            kept[o.obj.name] = _group_fit(g)
        elif h in _FITS:
            kept[o.obj.name] = (*_FITS[h], h)
        else:
            todo.append((o, h))
    view_hash = _view_hash(inp)
    views = [bpy.data.images.get(n) for n in ar_nodes.VIEW_IMAGES]
    view_needed = st.get("view_hash") != view_hash or not all(
        im is not None and ids.ours(im, key) for im in views)
    job = ARJob(inp, how, lighting, todo, kept, view_hash, view_needed)
    image = bpy.data.images.get(ar_nodes.TABLES_IMAGE)
    if lighting is None and st.get("env_hash") == inp.env_hash and image is not None \
            and ids.ours(image, key) and st.get("lights") is not None and not view_needed:
        job.lighting = False            # the stored tables and lights hold: nothing to compute
    return job


def _view_hash(inp):
    """What the receiver view depends on: the camera, the receivers, the map, the size."""
    h = hashlib.sha1(np.ascontiguousarray(inp.receiver_triangles, np.float32).tobytes())
    m = inp.model
    h.update(repr((np.round(m.matrix, 6).tolist(), m.lens, m.sensor_width, m.sensor_height,
                   m.sensor_fit, m.shift_x, m.shift_y, tuple(m.resolution),
                   tuple(m.pixel_aspect), inp.env_hash, tuple(inp.view_size))).encode())
    return h.hexdigest()


def _tables_image(key, lighting):
    old = bpy.data.images.get(ar_nodes.TABLES_IMAGE)
    reuse = {old.name: old} if old is not None and ids.ours(old, key) else {}
    with MapWriter(key, reuse) as writer:
        img = writer.write(ar_nodes.TABLES_IMAGE, ar_nodes.tables_pixels(lighting))
    img.use_fake_user = True
    img[STATE] = "tables"
    return img


def _view_images(key, view):
    """The receiver view as three packed float images (rows bottom first)."""
    olds = {n: bpy.data.images.get(n) for n in ar_nodes.VIEW_IMAGES}
    reuse = {n: im for n, im in olds.items() if im is not None and ids.ours(im, key)}
    sun, opened, cone = view.sun[::-1], view.open[::-1], view.cone[::-1]
    with MapWriter(key, reuse) as writer:
        for name, rgb, alpha in zip(ar_nodes.VIEW_IMAGES, (sun[..., :3], opened, cone[..., :3]),
                                    (sun[..., 3], None, cone[..., 3])):
            img = writer.write(name, rgb, alpha)
            img.use_fake_user = True
            img[STATE] = "view"


def _remove_groups(key):
    """Our node groups of the scene with ``key`` (the compositor's copy of the lamps' sphere
    group with them)."""
    for ng in [g for g in bpy.data.node_groups if ids.ours(g, key) and
               (ar_nodes.AR_KEY in g or g.bl_idname == ar_nodes.COMPOSITOR)]:
        bpy.data.node_groups.remove(ng)


def _centre(o):
    """The middle (3,) of object input ``o``'s world bounding box."""
    m = np.array(o.obj.matrix_world, float)
    p = o.triangles.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
    return 0.5 * (p.min(axis=0) + p.max(axis=0)) if len(p) else m[:3, 3]


def write(context, job, result) -> Outcome:
    """Write ``job``'s AR composite into ``context.scene`` (see ar_write.py)."""
    from ..core.ar.env_shadow import residual_floor
    scene = context.scene
    inp = job.inp
    key = ids.scene_key(scene, create=True)
    st = state(scene)
    warnings = list(inp.warnings)
    lighting = result.lighting if result.lighting not in (None, False) else None
    if lighting is not None:
        _LIGHTING.pop(inp.env_hash, None)
        while len(_LIGHTING) >= LIGHTINGS_KEPT:
            _LIGHTING.pop(next(iter(_LIGHTING)))
        _LIGHTING[inp.env_hash] = lighting
        image = _tables_image(key, lighting)
        st.update(env_hash=inp.env_hash, lights=ar_write.light_records(lighting),
                  floor=float(residual_floor(lighting)), bands=int(len(lighting.caps) + 1),
                  rows=int(lighting.irradiance.shape[0]))
    else:
        image = bpy.data.images[ar_nodes.TABLES_IMAGE]
    if result.view is not None:
        _view_images(key, result.view)
        st["view_hash"] = job.view_hash
    view = [bpy.data.images[n] for n in ar_nodes.VIEW_IMAGES]
    lights = ar_write.light_terms(st["lights"])
    bands, rows = int(st["bands"]), int(st["rows"])
    ar_write.restore_receivers(scene, key)
    ar_write.restore_world(key)
    ar_write.clear_compositor(scene)
    _remove_groups(key)
    camera = ar_nodes.camera_group(scene, inp.camera, key)
    shadows = []
    for o in inp.objects:
        centres, radii, hull, h = result.fits[o.obj.name]
        shadows.append(ar_nodes.shadow_group(o.obj, (centres, radii), hull,
                                             [lt[:3] for lt in lights], key, image, bands, rows,
                                             h))
    group = ar_nodes.composite_group(key, inp.photo, image, bands, rows, lights,
                                     float(st["floor"]), shadows, view)
    ar_write.add_aovs(scene)
    slots = ar_write.write_receivers(scene, inp.receivers, camera, inp.photo, key)
    # EEVEE's World: the ground under the lowest object, seen from its centre
    wanted = getattr(getattr(scene, "relight", None), "ar_eevee_ground", True)
    lowest, plane = None, None
    if inp.objects and wanted:
        centre, lowest = min(((_centre(o), o) for o in inp.objects), key=lambda co: co[0][2])
        plane = ground_plane(inp.receiver_triangles, centre[2], at=centre[:2])
    why = ar_write.write_world(scene, inp.model, inp.photo, plane,
                               lowest.obj if lowest is not None else None, key)
    if why:
        warnings.append(why)
    ar_write.write_compositor(scene, group, key)
    saved = dict(st.get("saved", {}))
    changed = ar_write.apply_settings(scene, saved)
    st["saved"] = saved
    if inp.photo.packed_file is None and inp.photo.source == "FILE":
        try:
            inp.photo.pack()
        except RuntimeError:
            warnings.append(f"The photo '{inp.photo.name}' could not be packed: a render farm "
                            "needs its file")
    if inp.env_image.packed_file is None:
        warnings.append(f"The environment '{inp.env_image.name}' is not packed into the .blend: "
                        "a render farm needs its file (File > External Data > Pack Resources)")
    st.update(version=ar_nodes.VERSION, camera=inp.camera.name, photo=inp.photo.name,
              receivers=[o.name for o in inp.receivers],
              objects=[o.obj.name for o in inp.objects], warnings=warnings)
    scene[STATE] = st
    spheres = sum(len(result.fits[o.obj.name][1]) for o in inp.objects)
    message = (f"AR {'set up' if job.how == 'setup' else 'updated'}: {len(inp.receivers)} "
               f"receiver(s), {len(inp.objects)} object(s) ({spheres} spheres), "
               f"{len(lights)} light(s) of the environment")
    if changed:
        message += f"; render settings set: {', '.join(changed)}"
    ar_draw.retry()     # the viewport's shadows draw again from the new data, even after a failure
    summary = {"receivers": len(inp.receivers), "objects": len(inp.objects), "slots": slots,
               "eevee_ground": ar_write.has_world(scene, key),
               "spheres": spheres, "lights": len(lights), "seconds": dict(result.seconds),
               "total_seconds": time.perf_counter() - job.t0}
    return Outcome(message, warnings, "ar", summary)


def setup(context, progress=None, how="setup") -> Outcome:
    """Read, compute and write at once (scripts, background mode)."""
    job = prepare(context, how)
    return job.write(context, job.compute(progress))


def clear(scene) -> dict:
    """Undo Set Up: the receivers' originals back, the compositor, the view layers' passes
    and the render settings as they were, our groups, materials and images removed."""
    if STATE not in scene:
        return {"ar": False}
    key = ids.scene_key(scene)
    st = state(scene)
    if key is not None:
        ar_write.restore_receivers(scene, key)
        ar_write.restore_world(key)
        _remove_groups(key)
        for img in [i for i in bpy.data.images if ids.ours(i, key) and i.get(STATE)]:
            bpy.data.images.remove(img)
    ar_write.clear_compositor(scene)
    ar_write.remove_aovs(scene)
    ar_write.restore_settings(scene, st.get("saved", {}))
    del scene[STATE]
    return {"ar": True}
