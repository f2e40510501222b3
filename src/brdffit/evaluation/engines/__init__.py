"""Real rendering engines drawing our exports, compared with our render of the fit (issue 34).

* :mod:`.threejs` – glTF exports in three.js (``MeshPhysicalMaterial``, WebGL in headless
  Chromium), in the ``sphere-distant`` / ``sphere-point`` scenes rebuilt in three.js.
"""
