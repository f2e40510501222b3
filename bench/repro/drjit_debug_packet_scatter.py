"""Minimal reproduction: Dr.Jit 1.5's debug mode drops in-bounds *packet* scatters.

Mitsuba 3.9.1 / Dr.Jit 1.5.0, ``llvm_ad_rgb``. A Python ``SamplingIntegrator`` returning three
AOV channels gives an image block of 8 channels (RGBA + 3 AOVs + weight), which Mitsuba
accumulates with packet scatters. With ``JitFlag.Debug`` on, Dr.Jit reports some of those
writes as out of bounds (``drjit.scatter_reduce(): out-of-bounds packet write to position
16376 in an array of size 8192``) and skips them: the sphere loses coverage (alpha = 0 on
hundreds more pixels than without debug mode). Without debug mode, or with debug mode and
``JitFlag.PacketOps`` off, the image is the same as with no AOVs. So the writes are in
bounds and the check is wrong; brdffit turns packet operations off in debug mode
(``BRDFFIT_DRJIT_DEBUG``).

Run: ``.venv/bin/python bench/repro/drjit_debug_packet_scatter.py`` (prints three lines; the
middle one shows the dropped writes).
"""

import os
import subprocess
import sys

CHILD = r"""
import sys
import numpy as np
import drjit as dr
import mitsuba as mi

mi.set_variant("llvm_ad_rgb")
debug, packets = sys.argv[1] == "1", sys.argv[2] == "1"
dr.set_flag(dr.JitFlag.Debug, debug)
dr.set_flag(dr.JitFlag.PacketOps, packets)


class AOVs(mi.SamplingIntegrator):
    def __init__(self):
        mi.SamplingIntegrator.__init__(self, mi.Properties())

    def aov_names(self):
        return ["a.R", "a.G", "a.B"]

    def sample(self, scene, sampler, ray, medium=None, active=True):
        si = scene.ray_intersect(ray, active)
        v = mi.Color3f(si.wi.z)
        return v, si.is_valid(), [v.x, v.y, v.z]


scene = mi.load_dict({
    "type": "scene", "shape": {"type": "sphere"}, "light": {"type": "constant"},
    "sensor": {"type": "perspective",
               "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 4], target=[0, 0, 0],
                                                        up=[0, 1, 0]),
               "film": {"type": "hdrfilm", "width": 32, "height": 32, "pixel_format": "rgba",
                        "rfilter": {"type": "box"}},
               "sampler": {"type": "independent", "sample_count": 4}}})
img = np.array(mi.render(scene, integrator=AOVs(), spp=4))
print(f"debug={debug} packet_ops={packets}: pixels with alpha 0: {(img[..., 3] == 0).sum()}")
"""


def main() -> None:
    from brdffit.evaluation.render._mitsuba import _find_llvm

    env = {**os.environ, "DRJIT_LIBLLVM_PATH": os.environ.get("DRJIT_LIBLLVM_PATH") or _find_llvm()}
    for debug, packets in (("0", "1"), ("1", "1"), ("1", "0")):
        res = subprocess.run([sys.executable, "-c", CHILD, debug, packets], env=env,
                             capture_output=True, text=True)
        reports = sum("out-of-bounds" in line for line in res.stderr.splitlines())
        print(res.stdout.strip() or res.stderr.strip()[-300:],
              f"({reports} out-of-bounds report(s) on stderr)")


if __name__ == "__main__":
    main()
