"""Our exports rendered by real engines, compared with our render of the fit.

* :mod:`.blender` – glTF files imported by Blender's own importer and rendered with Cycles
  (``bpy``, run in a child process).
"""
