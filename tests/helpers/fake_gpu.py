"""A stand-in for Blender's gpu module (unavailable in background mode) for the draw handlers'
frames (tests/test_ar_draw.py, test_sphere_nodes.py): the signatures of its documentation,
checking what a handler declares and sends as Blender's own code does: uniform names and sizes
against the create-info; a Buffer's data an array of the format's dtype (Blender copies its raw
bytes without looking at the dtype) and of its length; a texture's data long enough; a batch's
attributes those of the shader, each a C-contiguous float32 (n, k) with k the attribute's
component count (GPUVertBuf.attr_fill's check) and n > 0 (batch_for_shader reads the first
item for the attribute's length)."""
from __future__ import annotations

import types

import numpy as np

COMPONENTS = {"FLOAT": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


class FakeGpu:
    def __init__(self):
        self.log = []
        self.created = 0
        self.textures = []
        fake = self

        class Info:
            def __init__(self):
                self.inputs, self.constants, self.samplers = {}, {}, {}

            def vertex_in(self, slot, typ, name):
                self.inputs[name] = typ

            def push_constant(self, typ, name, size=0):
                self.constants[name] = (typ, size)

            def sampler(self, slot, typ, name):
                self.samplers[name] = typ

            def vertex_out(self, iface):
                pass

            def fragment_out(self, slot, typ, name):
                pass

            def vertex_source(self, src):
                assert "void main" in src

            fragment_source = vertex_source

        class Iface:
            def __init__(self, name):
                pass

            def smooth(self, typ, name):
                pass

        class Shader:
            def __init__(self, info):
                self.info = info
                self.names = list(info.constants)
                self.values = {}

            def bind(self):
                fake.log.append("bind")

            def uniform_float(self, name, value):
                typ, size = self.info.constants[name]
                want = {"FLOAT": 1, "VEC4": 4, "MAT4": 16}[typ]
                n = len(np.ravel(np.asarray(value, float)))
                assert size == 0 and n == want, (name, n, want)
                self.values[name] = np.ravel(np.asarray(value, float))

            def uniform_int(self, name, value):
                assert self.info.constants[name] == ("INT", 0) and isinstance(value, int)
                self.values[name] = value

            def uniform_sampler(self, name, tex):
                assert name in self.info.samplers
                assert (self.info.samplers[name] == "FLOAT_2D_ARRAY") == (tex.layers > 0)
                self.values[name] = tex

            def uniform_from_name(self, name):
                return self.names.index(name)

            def uniform_vector_float(self, location, buffer, length, count):
                name = self.names[location]
                typ, size = self.info.constants[name]
                assert buffer.format == "FLOAT"
                assert {"FLOAT": 1, "VEC4": 4}[typ] == length and size == count, name
                assert len(buffer.data) == length * count
                self.values[name] = np.asarray(buffer.data).reshape(count, length)

            def uniform_vector_int(self, location, buffer, length, count):
                name = self.names[location]
                typ, size = self.info.constants[name]
                assert buffer.format == "INT" and typ == "INT" and length == 1, name
                assert size == count and len(buffer.data) == count, name
                self.values[name] = np.asarray(buffer.data)

        class Buffer:
            DTYPES = {"FLOAT": np.float32, "INT": np.int32}

            def __init__(self, fmt, size, data):
                assert isinstance(data, np.ndarray) and data.dtype == self.DTYPES[fmt], \
                    (fmt, type(data), getattr(data, "dtype", None))
                assert data.flags.c_contiguous and data.size == size
                self.format, self.data = fmt, data.copy()

        class Texture:
            def __init__(self, size, layers=0, is_cubemap=False, format="RGBA8", data=None):
                w, h = size
                assert format == "RGBA32F" and data.format == "FLOAT"
                assert len(data.data) == w * h * max(layers, 1) * 4
                self.size, self.layers = size, layers
                self.filter, self.extend = None, None
                fake.textures.append(self)

            def filter_mode(self, use_filter):
                assert isinstance(use_filter, bool)
                self.filter = use_filter

            def extend_mode(self, mode="EXTEND"):
                assert mode in ("EXTEND", "REPEAT", "MIRRORED_REPEAT", "CLAMP_TO_BORDER")
                self.extend = mode

        def create_from_info(info):
            fake.created += 1
            return Shader(info)

        def batch_for_shader(shader, kind, content):
            assert kind == "TRIS" and set(content) == set(shader.info.inputs)
            for name, v in content.items():
                assert isinstance(v, np.ndarray) and v.dtype == np.float32, name
                assert v.flags.c_contiguous and v.ndim == 2, name
                assert v.shape[1] == COMPONENTS[shader.info.inputs[name]], name
                assert len(v) > 0, name
            n = {len(v) for v in content.values()}
            assert len(n) == 1 and n.pop() % 3 == 0
            fake.log.append("batch")
            return types.SimpleNamespace(draw=lambda sh: fake.log.append(
                ("draw", {k: v for k, v in sh.values.items()})))

        state = types.SimpleNamespace(
            blend_set=lambda m: self.log.append(("blend", m)),
            depth_test_set=lambda m: self.log.append(("depth", m)),
            depth_mask_set=lambda m: self.log.append(("mask", m)))
        self.gpu = types.SimpleNamespace(
            types=types.SimpleNamespace(GPUShaderCreateInfo=Info, GPUStageInterfaceInfo=Iface,
                                        Buffer=Buffer, GPUTexture=Texture),
            shader=types.SimpleNamespace(create_from_info=create_from_info), state=state)
        self.batch = types.SimpleNamespace(batch_for_shader=batch_for_shader)

    def draws(self):
        """The uniforms of each draw logged since the last clear."""
        return [e[1] for e in self.log if isinstance(e, tuple) and e[0] == "draw"]
