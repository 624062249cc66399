"""Materials the harness gives virtual objects (bpy)."""


def grey_diffuse(bpy, name="grey", albedo=0.5):
    """A Principled BSDF that renders as a Lambertian of ``albedo`` (rough, no specular);
    reused when ``name`` exists."""
    mat = bpy.data.materials.get(name)
    if mat is None:
        mat = bpy.data.materials.new(name)
        if mat.node_tree is None:            # Blender before 5.0: no node tree by default
            mat.use_nodes = True
        bsdf = mat.node_tree.nodes["Principled BSDF"]
        bsdf.inputs["Base Color"].default_value = (albedo, albedo, albedo, 1.0)
        bsdf.inputs["Roughness"].default_value = 1.0
        bsdf.inputs["Specular IOR Level"].default_value = 0.0
    return mat
