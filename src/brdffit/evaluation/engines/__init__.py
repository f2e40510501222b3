"""Our exports rendered by real engines, compared with our render of the fit.

* :mod:`.blender` – glTF files imported by Blender's own importer and rendered with Cycles
  (``bpy``, run in a child process), in ``sphere-distant`` rebuilt in Blender.
* :mod:`.threejs` – glTF exports in three.js (``MeshPhysicalMaterial``, WebGL in headless
  Chromium), in the ``sphere-distant`` / ``sphere-point`` scenes rebuilt in three.js.
"""
