"""Small glTF 2.0 files written by the tests themselves (pygltflib)."""
import base64

import numpy as np
import pygltflib as gl

FLOAT, USHORT, UINT = 5126, 5123, 5125
_TYPE = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}


class GltfBuilder:
    """Accumulates one binary buffer; `accessor()` appends an array."""

    def __init__(self):
        self.doc = gl.GLTF2(asset=gl.Asset(version="2.0"))
        self.blob = bytearray()

    def accessor(self, arr, component=FLOAT):
        arr = np.asarray(arr)
        arr = arr.reshape(len(arr), -1)
        dtype = {FLOAT: np.float32, USHORT: np.uint16, UINT: np.uint32}[component]
        data = np.ascontiguousarray(arr, dtype).tobytes()
        while len(self.blob) % 4:
            self.blob.append(0)
        self.doc.bufferViews.append(gl.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=len(data)))
        self.blob += data
        acc = gl.Accessor(bufferView=len(self.doc.bufferViews) - 1, componentType=component,
                          count=len(arr), type=_TYPE[arr.shape[1]])
        if component == FLOAT and arr.shape[1] == 3:
            acc.min, acc.max = arr.min(0).tolist(), arr.max(0).tolist()
        self.doc.accessors.append(acc)
        return len(self.doc.accessors) - 1

    def _view(self, data):
        while len(self.blob) % 4:
            self.blob.append(0)
        self.doc.bufferViews.append(gl.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=len(data)))
        self.blob += data
        return len(self.doc.bufferViews) - 1

    def sparse_accessor(self, base, count, positions, values, index_component=USHORT):
        """A float accessor of `count` rows stored sparse, as Blender writes
        morph targets: `base` rows (None: zeros, no buffer view) with rows
        `positions` replaced by `values`."""
        values = np.asarray(values, np.float32).reshape(len(positions), -1)
        width = values.shape[1]
        idx_dtype = {5121: np.uint8, USHORT: np.uint16, UINT: np.uint32}[index_component]
        acc = gl.Accessor(componentType=FLOAT, count=count, type=_TYPE[width],
                          sparse=gl.Sparse(count=len(positions),
                                           indices=gl.AccessorSparseIndices(
                                               bufferView=self._view(np.asarray(positions, idx_dtype).tobytes()),
                                               componentType=index_component),
                                           values=gl.AccessorSparseValues(bufferView=self._view(values.tobytes()))))
        if base is not None:
            acc.bufferView = self._view(np.asarray(base, np.float32).reshape(count, width).tobytes())
        self.doc.accessors.append(acc)
        return len(self.doc.accessors) - 1

    def material(self, colour, metallic=0.0, roughness=0.5, texture=None, name=None):
        """A pbrMetallicRoughness material; texture: (png bytes, texCoord,
        KHR_texture_transform dict or None), the image stored in the buffer."""
        pbr = gl.PbrMetallicRoughness(baseColorFactor=[*colour, 1.0], metallicFactor=metallic,
                                      roughnessFactor=roughness)
        if texture is not None:
            png, texcoord, transform = texture
            self.doc.images.append(gl.Image(bufferView=self._view(png), mimeType="image/png"))
            self.doc.textures.append(gl.Texture(source=len(self.doc.images) - 1))
            pbr.baseColorTexture = gl.TextureInfo(index=len(self.doc.textures) - 1, texCoord=texcoord,
                                                  extensions={"KHR_texture_transform": transform}
                                                  if transform else {})
        self.doc.materials.append(gl.Material(pbrMetallicRoughness=pbr, name=name))
        return len(self.doc.materials) - 1

    def mesh(self, positions, indices, targets=(), weights=None, joints=None, skin_weights=None):
        attrs = gl.Attributes(POSITION=self.accessor(positions))
        if joints is not None:
            attrs.JOINTS_0 = self.accessor(joints, USHORT)
            attrs.WEIGHTS_0 = self.accessor(skin_weights)
        prim = gl.Primitive(attributes=attrs, indices=self.accessor(np.asarray(indices).reshape(-1, 1), UINT),
                            targets=[{"POSITION": self.accessor(t)} for t in targets] or None)
        self.doc.meshes.append(gl.Mesh(primitives=[prim], weights=weights))
        return len(self.doc.meshes) - 1

    def node(self, **kw):
        self.doc.nodes.append(gl.Node(**kw))
        return len(self.doc.nodes) - 1

    def animation(self, channels, name="anim"):
        """channels: [(node, path, times, values, interpolation)]."""
        anim = gl.Animation(name=name, channels=[], samplers=[])
        for node, path, times, values, interp in channels:
            anim.samplers.append(gl.AnimationSampler(input=self.accessor(np.asarray(times)[:, None]),
                                                     output=self.accessor(values), interpolation=interp))
            anim.channels.append(gl.AnimationChannel(sampler=len(anim.samplers) - 1,
                                                     target=gl.AnimationChannelTarget(node=node, path=path)))
        self.doc.animations.append(anim)

    def save(self, path, roots):
        self.doc.scenes = [gl.Scene(nodes=roots)]
        self.doc.scene = 0
        blob = bytes(self.blob)
        if str(path).endswith(".glb"):
            self.doc.buffers = [gl.Buffer(byteLength=len(blob))]
            self.doc.set_binary_blob(blob)
            self.doc.save_binary(str(path))
        else:
            uri = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
            self.doc.buffers = [gl.Buffer(byteLength=len(blob), uri=uri)]
            self.doc.save_json(str(path))
