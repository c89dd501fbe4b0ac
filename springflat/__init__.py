"""springflat as a Python library: numpy arrays in, a flat pattern out.

>>> import springflat
>>> V, F = springflat.read_mesh("tests/data/scans/bunny_face.obj")
>>> layout = springflat.flatten(V, F).layout          # (V, 2) numpy array, in the mesh's units

* :func:`read_mesh` reads an OBJ, PLY, OFF or STL disk patch as ``(V, F)`` arrays.
* :func:`flatten` flattens ``(V, F)`` (or a ``trimesh.Trimesh``) and returns a :class:`Pattern`.
* :func:`write_pattern` writes a :class:`Pattern` as DXF, true-scale PDF or SVG, or OBJ with ``vt``.
* What they refuse raises :class:`MeshError` (the mesh), :class:`ParameterError` (an option) or
  :class:`OutputError` (a file to write), each a ``ValueError`` with a one-line message.

This package sits on top of the project (``golden_model`` for the algorithm, ``sim`` for the mesh files,
the start layouts, the command line's option handling and the writers) and nothing in the project imports it.
"""

from __future__ import annotations

from sim.version import installed_version

from golden_model.mesh import MeshError
from golden_model.params import ParameterError
from sim.outputs import OutputError

from .api import OPTIONS, MeshNote, Pattern, flatten, read_mesh, write_pattern

__all__ = ["flatten", "read_mesh", "write_pattern", "Pattern", "OPTIONS", "MeshNote", "MeshError", "ParameterError",
           "OutputError", "__version__"]

#: The installed version, as ``springflat --version`` prints it.
__version__ = installed_version()
