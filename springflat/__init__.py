"""springflat as a Python library: numpy arrays in, a flat pattern out.

>>> import springflat
>>> V, F = springflat.read_mesh("tests/data/scans/bunny_face.obj")
>>> layout = springflat.flatten(V, F).layout          # (V, 2) numpy array, in the mesh's units

* :func:`read_mesh` reads an OBJ, PLY, OFF or STL disk patch as ``(V, F)`` arrays.
* :func:`flatten` flattens ``(V, F)`` (or a ``trimesh.Trimesh``) and returns a :class:`Pattern`.
* :func:`write_pattern` writes a :class:`Pattern` as DXF, true-scale PDF or SVG, or OBJ with ``vt``.

This package sits on top of the project (``golden_model`` for the algorithm, ``sim`` for the command
line's option handling and the writers) and nothing in the project imports it.
"""

from __future__ import annotations

from sim.cli import installed_version

from .api import OPTIONS, MeshNote, Pattern, flatten, read_mesh, write_pattern

__all__ = ["flatten", "read_mesh", "write_pattern", "Pattern", "OPTIONS", "MeshNote", "__version__"]

#: The installed version, as ``springflat --version`` prints it.
__version__ = installed_version()
