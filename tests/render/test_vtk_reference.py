"""Pixels against VTK's GPU ray caster (vtkOpenGLGPUVolumeRayCastMapper, offscreen EGL).

Same volume, TF nodes (our LUT), opacity unit distance, sample distance and camera; jittering
off; each sample classified by its own value, as VTK does (our renderers pre-integrate by
default: ``preintegrated=False`` here). Unshaded pictures must agree to within 2/255 on average
and 40 dB PSNR.
"""

from __future__ import annotations

import numpy as np
import pytest

from helpers.tfs import tooth_tf
from helpers.vtkref import VTKScene, vtk_available
from intuitf.render import Camera, VolumeRenderer
from intuitf.tf import Gaussian, GaussianTF

pytestmark = pytest.mark.vtk

_REASON = vtk_available()
if _REASON:
    pytest.skip(_REASON, allow_module_level=True)

VIEWS = [
    Camera(projection="orthographic"),  # along +y, axis-aligned
    Camera(azimuth=35, elevation=25, fov=30),  # oblique perspective
]


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(((a.astype(np.float64) - b.astype(np.float64)) ** 2).mean())
    return 10 * np.log10(255.0**2 / max(mse, 1e-12))


def _neghip_tf() -> GaussianTF:
    return GaussianTF(
        (
            Gaussian(mean=0.25, width=0.06, height=0.04, color=(0.2, 0.4, 1.0)),
            Gaussian(mean=0.6, width=0.08, height=0.3, color=(1.0, 0.6, 0.2)),
        )
    )


@pytest.mark.parametrize("which", ["tooth", "neghip"])
def test_unshaded_matches_vtk_gpu_mapper(which, request):
    vol = request.getfixturevalue(which)
    tf = tooth_tf() if which == "tooth" else _neghip_tf()
    r = VolumeRenderer(vol, size=(128, 112), shading=False, sample_distance=0.5,
                       preintegrated=False)  # fmt: skip
    scene = VTKScene(r, "gpu")
    try:
        for cam in VIEWS:
            ours, ref = r.render(tf, cam), scene.render(tf, cam)
            assert ref.max() > 60  # VTK drew something
            d = np.abs(ours.astype(int) - ref.astype(int))
            assert d.mean() < 2.0, (which, cam, d.mean())
            assert _psnr(ours, ref) > 40.0, (which, cam, _psnr(ours, ref))
    finally:
        scene.close()


def test_shaded_resembles_vtk_gpu_mapper(tooth):
    """Shaded: a looser bound. VTK's shader takes its own on-the-fly gradient and light model
    (its specular term differs most), so only the overall picture can agree: measured mean
    0.8–1.7/255 and PSNR 33–40 dB on the tooth; bounds are set at mean < 4/255, PSNR > 28 dB.
    """
    r = VolumeRenderer(tooth, size=(128, 112), shading=True, preintegrated=False)
    scene = VTKScene(r, "gpu")
    try:
        for cam in VIEWS:
            ours, ref = r.render(tooth_tf(), cam), scene.render(tooth_tf(), cam)
            d = np.abs(ours.astype(int) - ref.astype(int))
            assert d.mean() < 4.0, (cam, d.mean())
            assert _psnr(ours, ref) > 28.0, (cam, _psnr(ours, ref))
    finally:
        scene.close()
