"""Mesh files: the OBJ, PLY, OFF and STL readers and the OBJ writer.

:func:`load_mesh` reads a file and returns a validated :class:`golden_model.mesh.Mesh`; the
readers themselves only parse (one module per format), and the topology and validation live in
:mod:`golden_model.mesh`.  Every failure raises :class:`golden_model.mesh.MeshError` with a one-line
message; so does a file that cannot be read (the OS error in words).
"""

from .load import MESH_SUFFIXES, load_mesh, load_mesh_with_notes, repair_hint, save_obj
from .obj import ObjContents, read_obj, read_obj_vertices

__all__ = ["MESH_SUFFIXES", "ObjContents", "load_mesh", "load_mesh_with_notes", "read_obj", "read_obj_vertices",
           "repair_hint", "save_obj"]
