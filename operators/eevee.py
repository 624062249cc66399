# SPDX-License-Identifier: GPL-3.0-or-later
"""``relight.eevee_light``: an irradiance volume over the relit room, baked, so that EEVEE lights
virtual objects with the relit surfaces as Cycles does (relight_addon/blender/eevee_probe.py)."""

import bpy

from .base import RelightOperator


def _modules():
    from ..relight_addon.blender import eevee_probe, write
    return eevee_probe, write


def status(scene):
    from ..relight_addon.blender import state
    return state.status(scene)


def last_result(scene):
    from ..relight_addon.blender import state
    return state.last_result(scene)


# A background bake's seconds: a start-up, then a cost per volume sample and ray, measured on
# this project's 2-core machine with EEVEE on Mesa's software GPU (benchmarks/results/
# eevee_bake.md; a GPU bakes faster)
BAKE_START_S, BAKE_RAY_S = 5.0, 4.5e-5


def bake_seconds(count, samples):
    """Predicted seconds of a background bake of ``count`` volume samples x ``samples`` rays."""
    return BAKE_START_S + BAKE_RAY_S * float(count) * float(samples)


def _duration(seconds):
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min"


class RELIGHT_OT_eevee_light(RelightOperator, bpy.types.Operator):
    """Place an irradiance volume over the relit room and bake it, so that EEVEE lights virtual
    objects with the relit room's light (Cycles does by itself).  Bake again after moving
    surfaces; lamp dimming is followed by a driver"""

    bl_idname = "relight.eevee_light"
    bl_label = "Light Virtual Objects in EEVEE"
    bl_options = {'REGISTER', 'UNDO'}

    spacing: bpy.props.FloatProperty(
        name="Spacing", description="Distance between the volume's light samples",
        default=0.25, min=0.05, soft_max=2.0, unit='LENGTH')
    bake: bpy.props.BoolProperty(
        name="Bake", description="Bake the volume now (Blender's light-probe bake)", default=True)
    samples: bpy.props.IntProperty(
        name="Samples", default=256, min=1, soft_max=2048,
        description="Rays per volume sample when baking: the bake's time grows with it "
                    "(Blender's default of 2048 took minutes headless, on a software GPU)")

    time_limit: bpy.props.FloatProperty(
        name="Time Limit", default=300.0, min=0.0, subtype='TIME_ABSOLUTE', unit='TIME_ABSOLUTE',
        description="In background mode (a script, a farm node) Blender's bake blocks until it "
                    "is done and cannot be cancelled: a bake predicted to take longer is not "
                    "started (0: no limit).  The prediction is a software GPU's, an upper bound "
                    "for a real one")

    @classmethod
    def disabled_reason(cls, context):
        _, write = _modules()
        if not status(context.scene) or not write.has_relight_data(context.scene):
            return "Run Precompute first: there is no relit room to light objects with"
        return None

    def execute(self, context):
        eevee_probe, _ = _modules()
        scene = context.scene
        st = status(scene)
        names = list(st.get("lamps", []))
        result = last_result(scene)
        if result is not None and names and all(len(m) == len(names)
                                                for m in result.maps.values()):
            shares = eevee_probe.lamp_shares(result, names)
        else:                                   # after a reload: no maps in memory
            shares = {n: 1.0 / len(names) for n in names} if names else {}
        probe = eevee_probe.fit_volume(scene, shares, self.spacing)
        if probe is None:
            self.report({'ERROR'}, "Relight: no relit surface in this scene")
            return {'CANCELLED'}
        rx, ry, rz = eevee_probe.resolution(probe.data)
        count = rx * ry * rz
        probe.data.bake_samples = self.samples
        if not self.bake:
            # the driver refers the intensity to the lamps as they are now (BAKED_KEY)
            self.report({'INFO'}, f"Relight: irradiance volume placed ({count} samples); bake "
                                  "it before changing the lamps (its intensity follows them "
                                  "from their present powers)")
            return {'FINISHED'}
        # Blender's own bake: a job with progress and cancel in the UI, blocking in background
        import time
        how = 'EXEC_DEFAULT' if bpy.app.background else 'INVOKE_DEFAULT'
        predicted = bake_seconds(count, self.samples)
        if bpy.app.background and self.time_limit > 0 and predicted > self.time_limit:
            self.report({'ERROR'}, f"Relight: the irradiance volume is placed but not baked: "
                                   f"{count} samples x {self.samples} rays would take about "
                                   f"{_duration(predicted)} here, past the "
                                   f"{self.time_limit:.0f} s Time Limit (raise Spacing, lower "
                                   "Samples, raise the limit, or bake it in Blender with a window)")
            return {'CANCELLED'}
        t0 = time.perf_counter()
        try:
            with context.temp_override(active_object=probe, object=probe,
                                       selected_objects=[probe]):
                bpy.ops.object.lightprobe_cache_bake(how, subset='ACTIVE')
        except RuntimeError as ex:              # no GPU context (a farm node, a server)
            self.report({'ERROR'}, f"Relight: the irradiance volume is placed but could not be "
                                   f"baked here ({str(ex).strip()}): bake it in Blender with a "
                                   "window (Bake in the volume's properties)")
            return {'CANCELLED'}
        self.report({'INFO'}, f"Relight: irradiance volume of {count} samples "
                              + (f"baked ({self.samples} rays each, "
                                 f"{time.perf_counter() - t0:.0f} s)" if bpy.app.background
                                 else "baking"))
        return {'FINISHED'}


classes = (RELIGHT_OT_eevee_light,)
