"""A small builder of binary glTF (.glb) files over pygltflib: one buffer, one view and accessor per array."""

from __future__ import annotations

import numpy as np
import pygltflib as gl

__all__ = ["GlbBuilder"]

_COMPONENT = {
    np.dtype(np.float32): gl.FLOAT,
    np.dtype(np.uint8): gl.UNSIGNED_BYTE,
    np.dtype(np.uint16): gl.UNSIGNED_SHORT,
    np.dtype(np.uint32): gl.UNSIGNED_INT,
}
_TYPE = {1: gl.SCALAR, 2: gl.VEC2, 3: gl.VEC3, 4: gl.VEC4, 16: gl.MAT4}


class GlbBuilder:
    """Collects arrays into one binary buffer; :meth:`to_bytes` returns the .glb file.

    Attributes:
        gltf: the document being built (nodes, meshes, skins, animations are appended by the caller).
    """

    def __init__(self, generator: str) -> None:
        self.gltf = gl.GLTF2(asset=gl.Asset(version="2.0", generator=generator), scene=0, scenes=[gl.Scene(nodes=[])])
        self._chunks: list[bytes] = []
        self._length = 0

    def add_accessor(self, array: np.ndarray, *, target: int | None = None, min_max: bool = False) -> int:
        """Append an array as a new buffer view and accessor.

        Args:
            array: (N,) scalars or (N, k) vectors with k in {2, 3, 4, 16} (16: a 4x4 matrix, column-major,
                already flattened); float32, uint8, uint16 or uint32.
            target: ``pygltflib.ARRAY_BUFFER`` / ``ELEMENT_ARRAY_BUFFER`` for mesh data, None for the rest.
            min_max: store the per-component min and max (required for POSITION and animation inputs).

        Returns:
            The accessor index.
        """
        array = np.ascontiguousarray(array)
        width = 1 if array.ndim == 1 else int(array.shape[1])
        data = array.tobytes()
        view = gl.BufferView(buffer=0, byteOffset=self._length, byteLength=len(data), target=target)
        self._chunks.append(data)
        self._length += len(data)
        padding = (-self._length) % 4
        if padding:
            self._chunks.append(b"\x00" * padding)
            self._length += padding
        self.gltf.bufferViews.append(view)
        accessor = gl.Accessor(
            bufferView=len(self.gltf.bufferViews) - 1, componentType=_COMPONENT[array.dtype], count=int(array.shape[0]),
            type=_TYPE[width],
        )
        if min_max:
            flat = array.reshape(array.shape[0], width)
            accessor.min = [float(v) for v in flat.min(axis=0)]
            accessor.max = [float(v) for v in flat.max(axis=0)]
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1

    def add_node(self, node: gl.Node) -> int:
        """Append a node; returns its index."""
        self.gltf.nodes.append(node)
        return len(self.gltf.nodes) - 1

    def to_bytes(self) -> bytes:
        """The .glb file (JSON chunk + one binary chunk)."""
        self.gltf.buffers = [gl.Buffer(byteLength=self._length)]
        self.gltf.set_binary_blob(b"".join(self._chunks))
        return b"".join(self.gltf.save_to_bytes())
